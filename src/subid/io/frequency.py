"""Frequency-response files: :func:`read_frd` and :func:`write_frd`.

Text (``.csv``, ``.tsv``, ``.txt``): one row per frequency, a header naming
the columns; lines starting with ``#`` are comments, and one of them may give
the sampling period, ``# dt = 0.01`` (0: continuous time; :func:`write_frd`
writes it first). One frequency column, named ``w`` (also ``omega``, ``rad/s``:
radians per time unit) or ``f``/``freq``/``frequency``/``hz`` (Hz, converted
with ``w = 2 pi f``), or any of these with a unit in brackets, which then
decides: ``w [Hz]`` is in Hz, ``Frequency [kHz]``, ``f (rad/s)``,
``Frequency [rpm]``, ``freq [cycles/min]`` (the units of MATLAB's
``FrequencyUnit``; the time unit of the data taken to be the second). A name
that states a unit itself (``hz``, ``f_hz``, ``w_rad``, ``rad/s``) must
agree with the unit in brackets, and an unknown unit is an error. For each
channel pair two columns
``<output>/<input>:<quantity>`` (for one input and one output the prefix may
be left out), with the quantities

* ``re`` and ``im`` (also ``real``, ``imag``): real and imaginary parts, or
* ``mag`` (also ``abs``, ``magnitude``, ``gain``: absolute value) or
  ``db`` (also ``mag_db``: 20 log10 of it), and ``phase`` (also
  ``phase_deg``: degrees) or ``phase_rad`` (radians).

A unit in brackets is understood: ``Magnitude [dB]``, ``Phase (deg)``. Optional ``<output>/<input>:std`` columns are the
standard deviations and ``<output>:coherence`` the squared coherences; the
weights of the fit (:class:`subid.FRData`'s ``weights``) are one ``weight``
column (one per frequency) or ``<output>/<input>:weight`` columns (one per
frequency and pair). Each of these is given for every pair (output) or none.
One pair's response has one representation (re and im, or one magnitude and
one phase); a magnitude (``mag``) is non-negative.

MATLAB ``.mat`` and NumPy ``.npz``: the variables of MATLAB's ``idfrd``,
``ResponseData`` (ny x nu x n_freq) and ``Frequency`` in ``FrequencyUnit``
(default ``rad/TimeUnit``; ``Hz``, ``kHz``, ``MHz``, ``GHz``, ``rpm``,
``rad/s``, ``rad/ms``, ``rad/min``, ``cycles/hr``, ... are converted to rad per
time unit; an unknown unit, and months or years, which have no fixed length,
are an error) with ``Ts`` (0 = continuous time; -1, MATLAB's unspecified
sample time, needs ``dt=``) and ``TimeUnit`` (default seconds: without it, the
time unit of ``Ts``, and of the data, is taken to be the second), or
subid's own ``w``, ``response`` (n_freq x ny x nu) and ``dt``, with
optional ``std``, ``coherence`` and ``weights``.
:func:`write_frd` writes both layouts (and ``std``/``coherence``/``weights``) into a
``.mat``/``.npz`` file, and real/imaginary columns (or ``db``/``phase`` with
``polar=True``) into a text file.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
from pathlib import Path

import numpy as np

from subid._validation import UNIFORM_RTOL, check_dt, checked_call
from subid.errors import DataError, FileReadError, OptionError
from subid.frdata import FRData
from subid.io._files import MAX_EXPANDED_BYTES, atomic_write, read_regular
from subid.io._frequency_units import KNOWN_UNITS, frequency_factor, seconds_per
from subid.io._npz import NpzError, load_npz
from subid.io.mat import mat_variables

__all__ = ["read_frd", "write_frd"]

_TEXT = (".csv", ".tsv", ".txt", ".dat")
_ARRAYS = (".mat", ".npz")
# name of a frequency column (lower case, unit in brackets removed) -> (factor to rad per
# time unit without a unit in brackets, whether the name itself states that unit)
_FREQUENCY_NAMES = {
    **dict.fromkeys(("w", "omega"), (1.0, False)),
    **dict.fromkeys(("f", "freq", "frequency"), (2 * math.pi, False)),
    **dict.fromkeys(("rad/s", "w_rad", "omega_rad", "freq_rad", "frequency_rad"), (1.0, True)),
    **dict.fromkeys(("hz", "f_hz", "freq_hz", "frequency_hz"), (2 * math.pi, True)),
}
_QUANTITIES = {
    "re": "re", "real": "re", "im": "im", "imag": "im", "imaginary": "im",
    "mag": "mag", "abs": "mag", "magnitude": "mag", "gain": "mag",
    "db": "db", "mag_db": "db", "magnitude_db": "db", "gain_db": "db",
    "phase": "deg", "phase_deg": "deg", "phase_rad": "rad",
    "std": "std", "coherence": "coh", "weight": "weight", "weights": "weight",
}
_UNIT_RE = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\])]*)[\])]\s*$")


def _normalise(name: str) -> tuple[str, str | None]:
    """``(base name, unit)`` of a header cell, lower case: ``'Phase (deg)' -> ('phase', 'deg')``."""
    text = name.strip().lower()
    match = _UNIT_RE.match(text)
    if match:
        return match.group("name").strip(), match.group("unit").strip()
    return text, None


def _frequency_column(header, shown):
    """``(index, factor to rad per time unit)`` of the frequency column of ``header``."""
    for k, cell in enumerate(header):
        match = _UNIT_RE.match(cell.strip())
        base, unit = (match.group("name").strip().lower(), match.group("unit").strip()) \
            if match else (cell.strip().lower(), None)
        named = _FREQUENCY_NAMES.get(base)
        if named is None:
            continue
        if unit is None:
            return k, named[0]
        factor = frequency_factor(unit)
        if factor is None:
            raise FileReadError(f"{shown}: frequency column {cell!r} has the unknown unit "
                                f"{unit!r}; known: {KNOWN_UNITS}", path=shown, line=1,
                                column=cell)
        if named[1] and not math.isclose(factor, named[0], rel_tol=1e-12):
            raise FileReadError(f"{shown}: frequency column {cell!r}: its name says "
                                f"{'Hz' if named[0] != 1 else 'rad per time unit'} but its "
                                f"unit says {unit}; rename the column or correct the unit",
                                path=shown, line=1, column=cell)
        return k, factor
    raise FileReadError(f"{shown}: no frequency column; name one 'w' (rad per time unit) or "
                        f"'f' (Hz), or give its unit: 'Frequency [kHz]'. Header: "
                        f"{', '.join(header)[:300]}", path=shown, line=1)


#: Units in brackets of a magnitude column (``'db...'``: any decibel unit, ``dB re 1 V/V``,
#: ``dBV``) and of a phase column; any other unit there is an error (read as linear
#: magnitude or as degrees, ``Phase [rads]`` was off by a factor 57).
_MAGNITUDE_UNITS = {"": "mag", "abs": "mag", "lin": "mag", "linear": "mag", "v/v": "mag",
                    "1": "mag", "-": "mag"}
_PHASE_UNITS = {"deg": "phase_deg", "degree": "phase_deg", "degrees": "phase_deg",
                "°": "phase_deg", "rad": "phase_rad", "rads": "phase_rad",
                "radian": "phase_rad", "radians": "phase_rad"}


def _quantity(cell: str, shown: str = ""):
    """``(pair or None, quantity)`` of a response column, or None; a magnitude or phase
    column whose unit in brackets is unknown is a :class:`FileReadError`."""
    text = cell.strip()
    pair, _, qty = text.rpartition(":")
    base, unit = _normalise(qty)
    if unit is not None and base in ("mag", "magnitude", "gain", "phase"):
        known = _PHASE_UNITS if base == "phase" else _MAGNITUDE_UNITS
        if base != "phase" and unit.replace(" ", "").startswith("db"):
            base = "db"
        elif unit in known:
            base = known[unit]
        else:
            raise FileReadError(
                f"{shown}: column {cell!r} has the unknown unit {unit!r}; a "
                + ("phase is in deg or rad" if base == "phase" else
                   "magnitude is linear (no unit, abs) or in dB (any 'dB...' unit)"),
                path=shown or None, line=1, column=cell)
    kind = _QUANTITIES.get(base)
    if kind is None:
        return None
    return (pair.strip() or None), kind


def _parse_pair(pair: str, shown: str):
    out, sep, inp = pair.partition("/")
    if not sep or not out.strip() or not inp.strip():
        raise FileReadError(f"{shown}: column prefix {pair!r} is not '<output>/<input>'",
                            path=shown, line=1)
    return out.strip(), inp.strip()


_DT_RE = re.compile(r"^#\s*(?:dt|ts)\s*[=:]\s*(?P<value>.*?)\s*$", re.IGNORECASE)


def _comment_dt(shown: str, lines) -> tuple[float, int] | None:
    """``(dt, line)`` of a ``# dt = <period>`` comment line of a text file, or None."""
    found = None
    for k, line in enumerate(lines):
        match = _DT_RE.match(line.strip())
        if match is None:
            continue
        text = match.group("value")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value) or value < 0:
            raise FileReadError(f"{shown}: line {k + 1}: {text!r} is not a sampling period; "
                                "write '# dt = <period>' (0 = continuous time)",
                                path=shown, line=k + 1)
        if found is not None and not _same_dt(found[0], value):
            raise FileReadError(f"{shown}: line {k + 1} says dt = {value:g} but line "
                                f"{found[1]} says dt = {found[0]:g}; keep one '# dt =' line",
                                path=shown, line=k + 1)
        found = found or (value, k + 1)
    return found


def _same_dt(a: float, b: float) -> bool:
    return a == b or math.isclose(a, b, rel_tol=UNIFORM_RTOL)


def _agreed_dt(shown: str, given, stated, where: str = "") -> float:
    """The sampling period: ``given`` (read_frd's ``dt``) or the file's ``stated`` one.

    ``stated`` is ``(dt, line)`` (line None for a variable of a .mat/.npz file) or
    None; when both are there they must agree.
    """
    if stated is None:
        return 0.0 if given is None else given
    value, line = stated
    if given is not None and not _same_dt(given, value):
        said = f"line {line}" if line is not None else where
        raise FileReadError(f"{shown}: dt={given:g} was passed but the file's {said} says "
                            f"dt = {value:g}{' (continuous time)' if value == 0 else ''}; "
                            "drop dt= (or correct the file)", path=shown, line=line)
    return value


def _read_text(shown: str, raw: bytes, ext: str, delimiter, dt) -> FRData:
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    lines = [ln for ln in text.splitlines()]
    body = [(k + 1, ln) for k, ln in enumerate(lines) if ln.strip() and not ln.lstrip()
            .startswith("#")]
    dt = _agreed_dt(shown, dt, _comment_dt(shown, lines))
    if len(body) < 2:
        raise FileReadError(f"{shown}: a frequency-response file needs a header line and at "
                            "least one row", path=shown)
    if delimiter is None:
        head = re.sub(r'"[^"]*"', "", body[0][1])        # a quoted name's characters do not count
        delimiter = "\t" if ext == ".tsv" or ("\t" in head and "," not in head) else \
            ";" if head.count(";") > head.count(",") else ","
    rows = list(csv.reader(io.StringIO("\n".join(ln for _, ln in body)), delimiter=delimiter))
    header = [c.strip() for c in rows[0]]
    k_w, w_factor = _frequency_column(header, shown)
    columns: dict = {}
    for k, cell in enumerate(header):
        if k == k_w:
            continue
        found = _quantity(cell, shown)
        if found is None:
            raise FileReadError(f"{shown}: column {cell!r} is neither the frequency nor a "
                                "response column ('<output>/<input>:re', ':im', ':mag', ':db', "
                                "':phase', ':phase_rad', ':std', '<output>:coherence')",
                                path=shown, line=1, column=cell)
        pair, kind = found
        if (pair, kind) in columns:
            raise FileReadError(f"{shown}: column {cell!r} repeats a quantity", path=shown,
                                line=1, column=cell)
        columns[(pair, kind)] = k
    values = np.empty((len(rows) - 1, len(header)))
    for r, row in enumerate(rows[1:]):
        line = body[r + 1][0]
        if len(row) != len(header):
            raise FileReadError(f"{shown}: line {line} has {len(row)} fields but the header has "
                                f"{len(header)}", path=shown, line=line)
        for c, cell in enumerate(row):
            try:
                values[r, c] = float(cell)
            except ValueError:
                raise FileReadError(f"{shown}: line {line}, column {header[c]!r}: {cell!r} is "
                                    "not a number", path=shown, line=line,
                                    column=header[c]) from None
    return _assemble(shown, values[:, k_w] * w_factor, values, columns, dt, header,
                     [ln for ln, _ in body[1:]])


def _assemble(shown, w, values, columns, dt, header, row_lines) -> FRData:
    """The FRData of a text file's ``values`` (one column per header cell)."""
    pairs: dict = {}
    coherence: dict = {}
    weight_column = None
    for (pair, kind), k in columns.items():
        if kind == "coh":
            coherence[pair] = k
            continue
        if kind == "weight" and pair is None:
            weight_column = k                          # one weight per frequency
            continue
        out, inp = ("y1", "u1") if pair is None else _parse_pair(pair, shown)
        pairs.setdefault((out, inp), {})[kind] = k
    outputs = list(dict.fromkeys(o for o, _ in pairs))
    inputs = list(dict.fromkeys(i for _, i in pairs))
    missing = [f"{o}/{i}" for o in outputs for i in inputs if (o, i) not in pairs]
    if missing:
        raise FileReadError(f"{shown}: no response columns for {', '.join(missing)}; every "
                            "output/input pair needs its own", path=shown, line=1)
    for kind in ("std", "weight"):
        _all_pairs_or_none(shown, pairs, kind)
    n = values.shape[0]
    G = np.empty((n, len(outputs), len(inputs)), dtype=complex)
    std = weights = None
    for (o, i), kinds in pairs.items():
        a, b = outputs.index(o), inputs.index(i)
        _one_representation(shown, f"{o}/{i}", kinds, header)
        if "mag" in kinds and (values[:, kinds["mag"]] < 0).any():
            r = int(np.flatnonzero(values[:, kinds["mag"]] < 0)[0])
            cell = header[kinds["mag"]]
            raise FileReadError(f"{shown}: line {row_lines[r]}, column {cell!r}: magnitude "
                                f"{values[r, kinds['mag']]:g} is negative; a magnitude is an "
                                "absolute value (put the sign into the phase)",
                                path=shown, line=row_lines[r], column=cell)
        if "re" in kinds and "im" in kinds:
            G[:, a, b] = values[:, kinds["re"]] + 1j * values[:, kinds["im"]]
        elif ("mag" in kinds or "db" in kinds) and ("deg" in kinds or "rad" in kinds):
            mag = values[:, kinds["mag"]] if "mag" in kinds else \
                10.0 ** (values[:, kinds["db"]] / 20.0)
            phase = np.deg2rad(values[:, kinds["deg"]]) if "deg" in kinds else \
                values[:, kinds["rad"]]
            G[:, a, b] = mag * np.exp(1j * phase)
        else:
            raise FileReadError(f"{shown}: {o}/{i} needs re and im, or a magnitude (mag or db) "
                                f"and a phase; found {sorted(kinds)}", path=shown, line=1)
        if "std" in kinds:
            if std is None:
                std = np.empty(G.shape)
            std[:, a, b] = values[:, kinds["std"]]
        if "weight" in kinds:
            if weights is None:
                weights = np.empty(G.shape)
            weights[:, a, b] = values[:, kinds["weight"]]
    if weight_column is not None:
        if weights is not None:
            raise FileReadError(f"{shown}: a 'weight' column (one weight per frequency) and "
                                "'<output>/<input>:weight' columns; keep one kind",
                                path=shown, line=1)
        weights = values[:, weight_column]
    coh = None
    if coherence:
        if None in coherence and len(outputs) > 1:
            raise FileReadError(f"{shown}: a 'coherence' column without an output; name it "
                                "'<output>:coherence' (one per output)", path=shown, line=1)
        coh = np.empty((n, len(outputs)))
        for pair, k in coherence.items():
            name = outputs[0] if pair is None else pair
            if name not in outputs:
                raise FileReadError(f"{shown}: coherence of unknown output {name!r}", path=shown)
            coh[:, outputs.index(name)] = values[:, k]
        lack = [o for o in outputs if o not in coherence and not (None in coherence)]
        if lack:
            raise FileReadError(f"{shown}: ':coherence' columns for "
                                f"{', '.join(o for o in outputs if o not in lack)[:200]} but "
                                f"not for {', '.join(lack)[:200]}; give them for every output "
                                "or for none", path=shown, line=1)
    return FRData(w, G, dt, weights=weights, std=std, coherence=coh, input_names=inputs,
                  output_names=outputs)


def _one_representation(shown, pair, kinds, header):
    """Refuse two representations of one response (re/im and a polar one, mag and db, ...)."""
    cart = [k for k in ("re", "im") if k in kinds]
    polar = [k for k in ("mag", "db", "deg", "rad") if k in kinds]
    clash = cart + polar if cart and polar else \
        next((g for g in (["mag", "db"], ["deg", "rad"]) if all(k in kinds for k in g)), None)
    if clash:
        cells = ", ".join(repr(header[kinds[k]]) for k in clash)
        raise FileReadError(f"{shown}: {pair} has columns {cells}, two representations of one "
                            "response; keep re and im, or one magnitude (mag or db) and one "
                            "phase (degrees or radians)", path=shown, line=1)


def _all_pairs_or_none(shown, pairs, kind):
    """Refuse a ``:<kind>`` column given for some output/input pairs only."""
    have = [f"{o}/{i}" for (o, i), kinds in pairs.items() if kind in kinds]
    if have and len(have) < len(pairs):
        lack = [f"{o}/{i}" for (o, i), kinds in pairs.items() if kind not in kinds]
        raise FileReadError(f"{shown}: ':{kind}' columns for {', '.join(have)[:200]} but not "
                            f"for {', '.join(lack)[:200]}; give them for every output/input "
                            "pair or for none", path=shown, line=1)


def _read_arrays(shown: str, raw: bytes, ext: str, dt, max_bytes) -> FRData:
    if ext == ".mat":
        variables = mat_variables(shown, raw=raw, max_bytes=max_bytes)
    else:
        try:
            variables = load_npz(io.BytesIO(raw), size=len(raw),
                                 max_expanded=MAX_EXPANDED_BYTES if max_bytes is None
                                 else int(max_bytes))
        except NpzError as exc:
            raise FileReadError(f"{shown}: not a readable .npz archive ({exc})",
                                path=shown) from None
    names = {k: v for k, v in variables.items() if not k.startswith("__")}

    def get(*keys):
        for key in keys:
            if key in names:
                return np.asarray(names[key])
        return None

    G = get("response")
    w = get("w")
    if G is not None and w is not None:
        G = np.asarray(G)
        file_dt, dt_name = get("dt"), "dt"
    else:
        G, w = get("ResponseData"), get("Frequency")
        if G is None or w is None:
            raise FileReadError(f"{shown}: needs the variables w and response (subid) or "
                                "Frequency and ResponseData (MATLAB idfrd); found "
                                f"{', '.join(sorted(names))[:300] or 'none'}", path=shown)
        G = np.asarray(G)
        if G.ndim == 3:
            G = np.moveaxis(G, 2, 0)                    # ny x nu x n_freq -> n_freq x ny x nu
        elif G.ndim == 1 or 1 in G.shape:
            G = G.reshape(-1)
        w = _matlab_frequencies(shown, w, get("FrequencyUnit"), get("TimeUnit"))
        file_dt, dt_name = get("Ts"), "Ts"
    w = np.asarray(w).reshape(-1)
    dt = _array_dt(shown, dt, file_dt, dt_name)
    std = get("std")
    coherence = get("coherence")
    weights = get("weights")
    if weights is not None and weights.ndim == 2 and weights.shape[1] == 1:
        weights = weights.reshape(-1)               # a .mat file's column of per-frequency weights
    return FRData(w, G, dt, weights=weights, std=std, coherence=coherence,
                  input_names=_strings(get("input_names", "InputName")),
                  output_names=_strings(get("output_names", "OutputName")))


def _text_of(value) -> str:
    """A MATLAB char array (or string) read by scipy.io as a Python string."""
    flat = np.asarray(value).reshape(-1)
    return "".join(str(v) for v in flat).strip() if flat.dtype.kind in "US" else \
        (str(np.asarray(flat[0]).reshape(-1)[0]).strip() if flat.size else "")


def _matlab_frequencies(shown: str, w, unit, time_unit):
    """MATLAB's ``Frequency`` in ``FrequencyUnit`` (and ``TimeUnit``) as rad per time unit."""
    seconds = 1.0
    if time_unit is not None and _text_of(time_unit):
        known = seconds_per(_text_of(time_unit))
        if known is None:
            raise FileReadError(f"{shown}: unknown TimeUnit {_text_of(time_unit)!r}; use "
                                "seconds, milliseconds, minutes, hours, ... (or convert the "
                                "model in MATLAB with chgTimeUnit)", path=shown)
        seconds = known
    name = "rad/TimeUnit" if unit is None or not _text_of(unit) else _text_of(unit)
    factor = frequency_factor(name, seconds)
    if factor is None:
        raise FileReadError(f"{shown}: unknown FrequencyUnit {name!r}; known: {KNOWN_UNITS} "
                            "(or convert in MATLAB with chgFreqUnit(sys, 'rad/s'))",
                            path=shown)
    try:
        w = np.asarray(w, dtype=float)
    except (TypeError, ValueError):
        raise FileReadError(f"{shown}: Frequency is not numeric", path=shown) from None
    return w if factor == 1.0 else w * factor


def _array_dt(shown: str, given, file_dt, name: str) -> float:
    """The sampling period of a .mat/.npz file: its ``dt``/``Ts`` variable and ``given``."""
    if file_dt is None:
        return _agreed_dt(shown, given, None)
    try:
        value = float(np.asarray(file_dt, dtype=float).reshape(-1)[0])
    except (TypeError, ValueError, IndexError):
        raise FileReadError(f"{shown}: variable {name} is not a number", path=shown) from None
    if value == -1 and name == "Ts":
        if given is None:
            raise FileReadError(f"{shown}: Ts = -1 (MATLAB's discrete time with an unspecified "
                                "sample time); pass the sampling period as dt= (--dt)",
                                path=shown)
        return given
    if not math.isfinite(value) or value < 0:
        raise FileReadError(f"{shown}: variable {name} = {value:g} is not a sampling period "
                            "(0 = continuous time)", path=shown)
    return _agreed_dt(shown, given, (value, None), where=f"variable {name}")


def _strings(value):
    if value is None:
        return None
    flat = value.reshape(-1)
    out = []
    for item in flat:
        item = np.asarray(item).reshape(-1)
        out.append(str(item[0]) if item.size else "")
    return out or None


@checked_call
def read_frd(path, *, dt=None, delimiter=None, max_bytes=None) -> FRData:
    """Read frequency-response data (see the module documentation for the layouts).

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv``, ``.tsv``, ``.txt``, ``.dat`` (text with a header), ``.mat``
        or ``.npz``.
    dt : float, optional
        Sampling period of a discrete-time response (0: continuous time).
        Default: the file's (a text file's ``# dt = <period>`` comment line,
        a ``.mat``/``.npz`` file's ``Ts``/``dt`` variable), else 0. A value
        that contradicts the file's is an error; MATLAB's ``Ts = -1``
        (discrete time, sample time unspecified) needs it.
    delimiter : str, optional
        Field delimiter of a text file (detected among ``,`` ``;`` TAB).
    max_bytes : int, optional
        Bytes a compressed ``.mat``/``.npz`` may expand to (see :func:`subid.read`).

    Returns
    -------
    FRData

    Raises
    ------
    DataFileNotFoundError
        No such file.
    FileReadError
        Unsupported extension, no frequency column, an unknown column, a
        missing channel pair, a cell that is not a number, a ``dt`` that
        contradicts the file's, ``Ts = -1`` without ``dt``.
    DataError
        The values are not valid frequency-response data (see :class:`subid.FRData`).
    """
    shown = os.fspath(path)
    ext = Path(shown).suffix.lower()
    if ext not in _TEXT + _ARRAYS:
        raise FileReadError(f"{shown}: unsupported extension {ext or '(none)'!r} for "
                            f"frequency-response data; use one of {', '.join(_TEXT + _ARRAYS)}",
                            path=shown)
    if dt is not None:
        dt = check_dt(dt, allow_zero=True)
    raw = read_regular(shown, what="frequency-response file")
    if not raw:
        raise FileReadError(f"file {shown} is empty", path=shown)
    if ext in _TEXT:
        return _read_text(shown, raw, ext, delimiter, dt)
    return _read_arrays(shown, raw, ext, dt, max_bytes)


@checked_call
def write_frd(frdata, path, *, polar: bool = False) -> None:
    """Write frequency-response data to a file that :func:`read_frd` reads back.

    Parameters
    ----------
    frdata : FRData
    path : str or os.PathLike
        ``.csv``/``.tsv``/``.txt`` (a first line ``# dt = <dt>``, columns ``w``, ``<output>/<input>:re``,
        ``:im``, or ``:db`` and ``:phase`` in degrees with ``polar=True``,
        then ``:std``, ``:weight`` (or one ``weight`` column for weights per
        frequency) and ``<output>:coherence`` when present; 17 significant
        digits), or ``.mat``/``.npz`` (``w``, ``response``, ``dt`` and
        MATLAB's ``Frequency``, ``ResponseData``, ``Ts``, names, ``std``,
        ``coherence``, ``weights``). Everything :class:`subid.FRData` holds
        is written.
    polar : bool
        Text files: magnitude in dB and phase in degrees instead of real and
        imaginary parts (rounding then loses the last digits).

    Raises
    ------
    DataError
        ``frdata`` is not an FRData; for a text file, a channel name the header
        cannot carry (empty, white space at an end, a line break, an output
        name with ``/``). Names holding the delimiter or quotes are quoted.
    OptionError
        Unsupported extension.
    FileWriteError
        The file cannot be written (the previous content is kept).
    """
    if not isinstance(frdata, FRData):
        raise DataError(f"write_frd expects a subid.FRData, got {type(frdata).__name__}")
    shown = os.fspath(path)
    ext = Path(shown).suffix.lower()
    if ext in (".csv", ".tsv", ".txt"):
        _write_text(frdata, shown, "\t" if ext == ".tsv" else ",", polar)
    elif ext in _ARRAYS:
        _write_arrays(frdata, shown, ext)
    else:
        raise OptionError(f"write_frd: unsupported extension {ext or '(none)'!r}; use .csv, "
                          ".tsv, .txt, .mat or .npz")


def _check_text_names(d: FRData) -> None:
    """Refuse channel names that a text file's header cannot carry back unchanged."""
    for which, names in (("output", d.output_names), ("input", d.input_names)):
        for name in names:
            problem = ("is empty" if not name.strip() else
                       "starts or ends with white space" if name != name.strip() else
                       "holds a line break" if "\n" in name or "\r" in name else
                       "holds '/', which separates output and input in the header"
                       if which == "output" and "/" in name else None)
            if problem:
                raise DataError(f"write_frd: {which} name {name!r} {problem}; rename the "
                                "channel (or write a .mat/.npz file)")


def _write_text(d: FRData, path: str, delim: str, polar: bool) -> None:
    _check_text_names(d)
    header = ["w"]
    cols = [d.w]
    for i, out in enumerate(d.output_names):
        for j, inp in enumerate(d.input_names):
            g = d.response[:, i, j]
            if polar:
                with np.errstate(divide="ignore"):
                    header += [f"{out}/{inp}:db", f"{out}/{inp}:phase"]
                    cols += [20 * np.log10(np.abs(g)), np.rad2deg(np.angle(g))]
            else:
                header += [f"{out}/{inp}:re", f"{out}/{inp}:im"]
                cols += [g.real, g.imag]
            if d.std is not None:
                header.append(f"{out}/{inp}:std")
                cols.append(d.std[:, i, j])
            if d.weights is not None and d.weights.ndim == 3:
                header.append(f"{out}/{inp}:weight")
                cols.append(d.weights[:, i, j])
    if d.weights is not None and d.weights.ndim == 1:
        header.append("weight")
        cols.append(d.weights)
    if d.coherence is not None:
        for i, out in enumerate(d.output_names):
            header.append(f"{out}:coherence")
            cols.append(d.coherence[:, i])
    table = np.column_stack(cols)
    if polar and not np.isfinite(table).all():
        raise DataError("write_frd: a zero response has no finite level in dB; write "
                        "real and imaginary parts (polar=False)")
    with atomic_write(path, "w", encoding="utf-8", what="frequency-response file") as fh:
        fh.write(f"# dt = {float(d.dt)!r}\n")
        csv.writer(fh, delimiter=delim, lineterminator="\n").writerow(header)  # quoted as needed
        for row in table:
            fh.write(delim.join(repr(float(v)) for v in row) + "\n")


def _write_arrays(d: FRData, path: str, ext: str) -> None:
    names_in = np.empty((1, d.n_inputs), dtype=object)
    names_in[0, :] = list(d.input_names)
    names_out = np.empty((1, d.n_outputs), dtype=object)
    names_out[0, :] = list(d.output_names)
    variables = {"w": d.w, "response": d.response, "dt": np.array(d.dt),
                 "Frequency": d.w.reshape(-1, 1), "ResponseData": np.moveaxis(d.response, 0, 2),
                 "Ts": np.array(d.dt)}
    if d.std is not None:
        variables["std"] = d.std
    if d.weights is not None:
        variables["weights"] = d.weights
    if d.coherence is not None:
        variables["coherence"] = d.coherence
    if ext == ".mat":
        import scipy.io
        variables.update(InputName=names_in, OutputName=names_out)
        with atomic_write(path, "wb", what="frequency-response file") as fh:
            scipy.io.savemat(fh, variables, format="5", do_compression=False, oned_as="column")
    else:
        variables.update(input_names=np.array(d.input_names),
                         output_names=np.array(d.output_names))
        with atomic_write(path, "wb", what="frequency-response file") as fh:
            np.savez(fh, **variables)
