"""Bundled DaISy input/output data sets.

The files in ``subid/datasets/data`` are unmodified records from DaISy, the
Database for the Identification of Systems. Cite them as: De Moor B.L.R.
(ed.), *DaISy: Database for the Identification of Systems*, Department of
Electrical Engineering, ESAT/SISTA, K.U.Leuven, Belgium, plus the references
of each set (see :func:`info`).

>>> from subid import datasets
>>> data = datasets.load("dryer")
>>> data.n_samples, data.dt
(1000, 0.08)
>>> datasets.info("dryer")["dt_known"]
False

Where DaISy gives no sampling time, ``dt`` is 1 (time counted in samples)
and ``info(name)["dt_known"]`` is False. Index columns and DaISy's ``Yr``
columns of ``powerplant`` are not part of the returned record.
"""

from __future__ import annotations

import copy
import difflib
import functools
from importlib import resources
from io import StringIO

import numpy as np

from subid.data import IOData
from subid.errors import DataError, FileReadError

__all__ = ["names", "load", "info"]

_DAISY = ("De Moor B.L.R. (ed.), DaISy: Database for the Identification of Systems, "
          "Department of Electrical Engineering, ESAT/SISTA, K.U.Leuven, Belgium")
_NO_TS = "DaISy gives no sampling time; dt = 1 means time is counted in samples."

# Column numbers below are 0-based indices into the .dat file (DaISy's
# descriptions count from 1). "index" is a column holding the sample number
# 1..N (or, with "time_step", the time in seconds), checked on loading.
_DATASETS: dict[str, dict] = {
    "dryer": dict(
        file="dryer.dat", shape=(1000, 2),
        description=("Laboratory setup acting like a hair dryer: air is fanned through a "
                     "tube and heated at the inlet; the input is the voltage over the heating "
                     "device, the output the air temperature at the outlet (thermocouple)."),
        source=_DAISY + "; contributed by W. Favoreel (KU Leuven). References: Ljung, System "
               "Identification: Theory for the User, 1987; Ljung, System Identification "
               "Toolbox for use with MATLAB, 1991.",
        kind="real (lab setup)",
        inputs={0: "voltage"}, outputs={1: "temperature"},
        dt=0.08, dt_known=False,
        dt_note=("DaISy does not state the sampling time. The record is the Feedback PT326 "
                 "hair-dryer data that MATLAB ships as the file dryer2.mat (load dryer2; not "
                 "this package's dataset:dryer2, an industrial dryer), whose examples use "
                 "Ts = 0.08 s, so dt = 0.08 s is very likely but not confirmed by DaISy."),
        notes="The input takes only the two values 3.41 and 6.41 (binary excitation)."),
    "ballbeam": dict(
        file="ballbeam.dat", shape=(1000, 2),
        description="Ball-and-beam practicum at ESAT-SISTA: input is the beam angle, output "
                    "the position of the ball.",
        source=_DAISY + "; contributed by P. Van Overschee. Reference: Van Overschee P., "
               "Subspace identification: theory, implementation, application, PhD thesis, "
               "K.U.Leuven, 1995, pp. 200-206.",
        kind="real (lab setup)",
        inputs={0: "beam_angle"}, outputs={1: "ball_position"},
        dt=0.1, dt_known=True, dt_note="Sampling time 0.1 s (DaISy).", notes=""),
    "robot_arm": dict(
        file="robot_arm.dat", shape=(1024, 2),
        description=("Flexible robot arm installed on an electrical motor: input is the "
                     "measured reaction torque of the structure on the ground, output the "
                     "acceleration of the flexible arm. The input is a periodic sine sweep."),
        source=_DAISY + "; data provided by H. Van Brussel and J. Swevers (KU Leuven PMA).",
        kind="real (lab setup)",
        inputs={0: "torque"}, outputs={1: "acceleration"},
        dt=1.0, dt_known=False, dt_note=_NO_TS, notes=""),
    "exchanger": dict(
        file="exchanger.dat", shape=(4000, 3), index=0,
        description=("Liquid-saturated steam heat exchanger: water heated by pressurized "
                     "saturated steam through a copper tube. Input is the liquid flow rate, "
                     "output the outlet liquid temperature; steam temperature and inlet "
                     "liquid temperature are kept at their nominal values."),
        source=_DAISY + "; contributed by S. Bittanti (Politecnico di Milano). Reference: "
               "Bittanti S. and Piroddi L., Nonlinear identification and control of a heat "
               "exchanger: a neural network approach, J. Franklin Institute, 1996.",
        kind="real (plant)",
        inputs={1: "flow_rate"}, outputs={2: "outlet_temperature"},
        dt=1.0, dt_known=True, dt_note="Sampling time 1 s (DaISy).",
        notes=("Column 1 of the file (sample index 1..4000) is not part of the record. "
               "Non-minimum-phase; also used as a nonlinear benchmark, so a linear model "
               "fits only approximately.")),
    "CD_player_arm": dict(
        file="CD_player_arm.dat", shape=(2048, 4),
        description=("Mechanical construction of a CD player arm: the inputs are the forces "
                     "of the mechanical actuators, the outputs are related to the tracking "
                     "accuracy of the arm. Measured in closed loop and converted to open-loop "
                     "equivalent data; the inputs are highly colored."),
        source=_DAISY + "; data provided by R. de Callafon (TU Delft), contributed by W. "
               "Favoreel. Reference: Van den Hof P. and Schrama R.J.P., An indirect method "
               "for transfer function estimation from closed loop data, Automatica 29(6), "
               "1993, pp. 1523-1527.",
        kind="real (closed-loop data converted to open-loop equivalent)",
        inputs={0: "force1", 1: "force2"}, outputs={2: "tracking1", 3: "tracking2"},
        dt=1.0, dt_known=False, dt_note=_NO_TS,
        notes=("DaISy's description numbers the output columns 1-2, a typo for 3-4 "
               "(the layout used here, as in the Octave test script).")),
    "glassfurnace": dict(
        file="glassfurnace.dat", shape=(1247, 10), index=0,
        description=("Philips glass furnace: inputs are two heating inputs and a cooling "
                     "input, outputs are 6 temperature sensors in a cross section of the "
                     "furnace."),
        source=_DAISY + "; contributed by P. Van Overschee. References: Van Overschee P. and "
               "De Moor B., N4SID: Subspace algorithms for the identification of combined "
               "deterministic-stochastic systems, Automatica 30(1), 1994, pp. 75-93; Van "
               "Overschee's PhD thesis, 1995.",
        kind="real (industrial)",
        inputs={1: "heating1", 2: "cooling", 3: "heating2"},
        outputs={k: f"temperature{k - 3}" for k in range(4, 10)},
        dt=1.0, dt_known=False, dt_note="The sampling time is left blank in DaISy; dt = 1 "
                                        "means time is counted in samples.",
        notes=("Column 1 of the file (sample index) is not part of the record. Every signal "
               "is already normalised to about zero mean and unit variance.")),
    "dryer2": dict(
        file="dryer2.dat", shape=(867, 7), index=0,
        description=("Industrial dryer (Cambridge Control Ltd). Inputs: fuel flow rate, hot "
                     "gas exhaust fan speed, rate of flow of raw material. Outputs: dry bulb "
                     "temperature, wet bulb temperature, moisture content of raw material."),
        source=_DAISY + "; contributed by J. Maciejowski (Cambridge University). References: "
               "Maciejowski J.M., Parameter estimation of multivariable systems using "
               "balanced realizations, in Bittanti (ed.), Identification, Adaptation, "
               "Learning, Springer, 1996; Chou C.T. and Maciejowski J.M., IEEE Trans. "
               "Automatic Control 42(7), 1997, pp. 956-974.",
        kind="real (industrial)",
        inputs={1: "fuel_flow", 2: "fan_speed", 3: "material_flow"},
        outputs={4: "dry_bulb_temperature", 5: "wet_bulb_temperature", 6: "moisture_content"},
        dt=10.0, dt_known=True, dt_note="Sampling time 10 s (DaISy).",
        notes=("Not MATLAB's dryer2 (that is the hair dryer, 'dryer' here). Column 1 of the "
               "file (sample index) is not part of the record.")),
    "powerplant": dict(
        file="powerplant.dat", shape=(200, 12), index=0,
        description=("120 MW power plant at Pont-sur-Sambre (France), normal operating "
                     "records. Inputs: gas flow, turbine valves opening, super heater spray "
                     "flow, gas dampers, air flow. Outputs: steam pressure, main steam "
                     "temperature, reheat steam temperature."),
        source=_DAISY + "; contributed by P. Van Overschee. References: Guidorzi R.P. and "
               "Rossi P., Identification of a power plant from normal operating records, "
               "Automatic Control Theory and Applications 2, 1974, pp. 63-67; Moonen M. et "
               "al., Int. J. Control 49, 1989, pp. 219-232.",
        kind="real (normal operating records)",
        inputs={1: "gas_flow", 2: "turbine_valves", 3: "spray_flow", 4: "gas_dampers",
                5: "air_flow"},
        outputs={6: "steam_pressure", 7: "main_steam_temperature",
                 8: "reheat_steam_temperature"},
        dt=1228.8, dt_known=True, dt_note="Sampling time 1228.8 s (DaISy).",
        notes=("The file has 12 columns: sample index, 5 inputs, 3 outputs, and DaISy's "
               "undocumented 'Yr' (columns 10-12, apparently a reconstructed output), which "
               "is ignored. DaISy's own snippet (U = cols 1-5) is off by the index column.")),
    "winding": dict(
        file="winding.dat", shape=(2500, 7),
        description=("Test set-up of an industrial winding process. Inputs: angular speeds "
                     "of reels 1, 2 and 3, set-point currents of motors 1 and 2. Outputs: web "
                     "tension between reels 1 and 2, and between reels 2 and 3."),
        source=_DAISY + ".",
        kind="real (test set-up)",
        inputs={0: "reel1_speed", 1: "reel2_speed", 2: "reel3_speed", 3: "motor1_current",
                4: "motor2_current"},
        outputs={5: "tension12", 6: "tension23"},
        dt=0.1, dt_known=True, dt_note="Sampling time 0.1 s (DaISy).",
        notes="The file has CRLF line endings."),
    "evaporator": dict(
        file="evaporator.dat", shape=(6305, 6),
        description=("Four-stage evaporator. Inputs: feed flow, vapour flow to the first "
                     "stage, cooling-water flow. Outputs: dry-matter content, flow and "
                     "temperature of the outcoming product."),
        source=_DAISY + ".",
        kind="real (plant)",
        inputs={0: "feed_flow", 1: "vapour_flow", 2: "cooling_water_flow"},
        outputs={3: "dry_matter", 4: "product_flow", 5: "product_temperature"},
        dt=1.0, dt_known=False, dt_note="The sampling time is not recorded with these data; "
                                        "dt = 1 means time is counted in samples.",
        notes=""),
    "steamgen": dict(
        file="steamgen.dat", shape=(9600, 9), index=0, time_step=3.0,
        description=("Simulated data from a model of a steam generator at Abbott Power "
                     "Plant: 4 inputs, 4 outputs."),
        source=_DAISY + ".",
        kind="simulated",
        inputs={k: f"u{k}" for k in range(1, 5)}, outputs={k: f"y{k - 4}" for k in range(5, 9)},
        dt=3.0, dt_known=True,
        dt_note="Sampling time 3 s, from the file's time column (0, 3, 6, ... s).",
        notes="Column 1 of the file (time in seconds) is not part of the record; the "
              "signals are not named in the description that was available."),
}


def names() -> list[str]:
    """Names of the bundled data sets.

    Returns
    -------
    list of str
        Names accepted by :func:`load` and :func:`info`, in alphabetical order.
    """
    return sorted(_DATASETS, key=str.lower)


def _lookup(name) -> tuple[str, dict]:
    if isinstance(name, str):
        if name in _DATASETS:
            return name, _DATASETS[name]
        folded = {k.lower(): k for k in _DATASETS}
        if name.lower() in folded:
            key = folded[name.lower()]
            return key, _DATASETS[key]
    close = difflib.get_close_matches(str(name), names(), n=1)
    hint = f" Did you mean {close[0]!r}?" if close else ""
    raise DataError(f"unknown data set {name!r}; available: {', '.join(names())}.{hint}")


@functools.lru_cache(maxsize=None)
def _table(name: str) -> np.ndarray:
    meta = _DATASETS[name]
    ref = resources.files(__name__).joinpath("data", meta["file"])
    try:
        text = ref.read_text(encoding="ascii")
        table = np.loadtxt(StringIO(text), dtype=np.float64, ndmin=2)
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise FileReadError(f"the bundled data file {meta['file']} cannot be read ({exc}); "
                            "the subid installation may be damaged", path=str(ref)) from None
    if table.shape != meta["shape"]:
        raise FileReadError(f"the bundled data file {meta['file']} has shape {table.shape}, "
                            f"expected {meta['shape']}; the subid installation may be damaged",
                            path=str(ref))
    if "index" in meta:
        n = table.shape[0]
        expected = meta.get("time_step", 1.0) * np.arange(n) + (0.0 if "time_step" in meta
                                                                else 1.0)
        if not np.allclose(table[:, meta["index"]], expected, rtol=0, atol=1e-6):
            raise FileReadError(f"the bundled data file {meta['file']}: column "
                                f"{meta['index'] + 1} is not the expected index/time column",
                                path=str(ref))
    table.setflags(write=False)
    return table


def load(name: str) -> IOData:
    """Load a bundled DaISy data set.

    Parameters
    ----------
    name : str
        One of :func:`names` (case is ignored).

    Returns
    -------
    IOData
        The record, with named channels and the sampling time of
        :func:`info` (``dt = 1``, counted in samples, where DaISy gives none).

    Raises
    ------
    DataError
        ``name`` is not a bundled data set.

    Examples
    --------
    >>> from subid import datasets
    >>> data = datasets.load("powerplant")
    >>> data.n_inputs, data.n_outputs, data.dt
    (5, 3, 1228.8)
    """
    key, meta = _lookup(name)
    table = _table(key)
    in_cols, out_cols = list(meta["inputs"]), list(meta["outputs"])
    return IOData(table[:, in_cols], table[:, out_cols], dt=meta["dt"],
                  input_names=list(meta["inputs"].values()),
                  output_names=list(meta["outputs"].values()))


def info(name: str) -> dict:
    """Describe a bundled data set.

    Parameters
    ----------
    name : str
        One of :func:`names` (case is ignored).

    Returns
    -------
    dict
        Keys: ``name``, ``file``, ``description``, ``source`` (citation and
        references), ``kind`` (real or simulated), ``n_samples``,
        ``n_inputs``, ``n_outputs``, ``input_names``, ``output_names``,
        ``input_columns`` and ``output_columns`` (1-based columns of the
        file, as in DaISy's descriptions), ``dt``, ``dt_known`` (False when
        DaISy does not state the sampling time), ``dt_note`` (where ``dt``
        comes from, with its caveat) and ``notes``.

    Raises
    ------
    DataError
        ``name`` is not a bundled data set.
    """
    key, meta = _lookup(name)
    return copy.deepcopy({
        "name": key,
        "file": meta["file"],
        "description": meta["description"],
        "source": meta["source"],
        "kind": meta["kind"],
        "n_samples": meta["shape"][0],
        "n_inputs": len(meta["inputs"]),
        "n_outputs": len(meta["outputs"]),
        "input_names": list(meta["inputs"].values()),
        "output_names": list(meta["outputs"].values()),
        "input_columns": [k + 1 for k in meta["inputs"]],
        "output_columns": [k + 1 for k in meta["outputs"]],
        "dt": meta["dt"],
        "dt_known": meta["dt_known"],
        "dt_note": meta["dt_note"],
        "notes": meta["notes"],
    })
