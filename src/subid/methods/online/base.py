"""The contract of the online identifiers, and a tracker that runs one over a record.

:class:`OnlineIdentifier` is the base of :class:`subid.RecursiveSubspace`
(discrete time, seed 001) and :class:`subid.AdaptiveIdentifier` (continuous
time, seed 000). Every online identifier:

* is built from keyword settings that the constructor only validates and
  stores, unchanged, under their own names (:meth:`~OnlineIdentifier.get_params`
  returns them; ``type(ident)(**ident.get_params())`` is a fresh identifier
  with the same settings);
* takes samples with ``update(u, y=None, t=None)``: arrays (one sample or a
  chunk, time on axis 0) or an :class:`~subid.data.IOData` record, with
  optional time stamps ``t``; the result does not depend on how the stream is
  cut into chunks, and a rejected chunk (a :class:`~subid.errors.DataError`)
  leaves the identifier unchanged;
* has ``n_samples``, ``t`` (time of the latest sample, None before the
  first), ``order``, ``n_inputs``, ``n_outputs``, the current ``model``
  (before enough data: :class:`~subid.errors.TooFewSamplesError`, never a zero
  model; a model whose estimate is incomplete or not converged comes with a
  :class:`~subid.errors.NotConvergedWarning` saying why), ``state`` (at the latest sample) and ``history``, a bounded dict
  of snapshots in one format that :func:`subid.plot.convergence` reads:
  ``sample`` (k,), ``t`` (k,), ``poles`` (k, order) complex and ``A``, ``B``,
  ``C``, ``D`` (k, ...) of the model at each snapshot;
* saves its whole state with ``save(path)`` and comes back with
  ``Class.load(path)`` (checkpoint kind ``subid.<Class>``); continuing a
  loaded identifier gives the estimates of a run that never stopped.

:class:`Tracker` feeds a record to an identifier in chunks, snapshots the
model (poles and Markov parameters) for the convergence plot and writes
periodic checkpoints with their convergence trace; ``subid track`` is a thin
command-line layer over it.
"""

from __future__ import annotations

import abc
import contextlib
import hashlib
import inspect
import math
import os
import warnings

import numpy as np

from subid._validation import HUGE_VALUE, UNIFORM_RTOL, same_period
from subid.errors import (
    CheckpointError,
    DataError,
    ResourceLimitError,
    SubidError,
)

__all__ = ["OnlineIdentifier", "Tracker", "history_dict", "markov_parameters", "with_names"]

_FLOAT64 = np.dtype(np.float64)


#: Largest state an online identifier may allocate (the memory of its statistics and
#: history, in bytes): beyond it the constructor raises
#: :class:`subid.errors.ResourceLimitError` before allocating (as
#: :data:`subid.statistic.hankel.FACTOR_BYTES_LIMIT` for a Hankel statistic).
STATE_BYTES_LIMIT = 2 ** 31


def check_state_bytes(nbytes: float, who: str, what: str, hint: str) -> None:
    """Raise :class:`ResourceLimitError` when an identifier's state of ``nbytes``
    bytes (``what``: its sizes) exceeds :data:`STATE_BYTES_LIMIT`; ``hint`` says
    which settings to reduce."""
    if nbytes > STATE_BYTES_LIMIT:
        raise ResourceLimitError(
            f"{who}: {what} need {nbytes / 2**30:.3g} GiB of memory (limit "
            f"{STATE_BYTES_LIMIT / 2**30:g} GiB), more than an online identifier may "
            f"allocate; {hint}")


def one_sample(values, channels: int):
    """``values`` as a (1, ``channels``) C-contiguous float64 view when it is
    one finite sample given as a contiguous, writeable 1-D float64 ndarray of
    ``channels`` entries (the common call of a stream); otherwise None, and
    the caller validates ``values`` the general way
    (:func:`subid._validation.as_chunk`, which returns the same array for
    such a sample and raises the errors). A read-only array takes the general
    way too: the compiled kernels are specialised on the arrays' writeable
    flag, and the identifiers give them writeable arrays only
    (:func:`writeable`), so that the kernels compiled at install serve every call.

    The caller checks ``type(values) is np.ndarray``. The dtype is compared
    by identity first (the usual float64 descriptor), then by equality (an
    equal descriptor object made elsewhere, e.g. by scipy). Finiteness is tested
    on the sum of the values (NaN and inf propagate into it), entry by entry
    only if the sum is not finite (an overflow).
    """
    dtype = values.dtype
    flags = values.flags
    if (dtype is _FLOAT64 or dtype == _FLOAT64) and values.shape == (channels,) \
            and flags.c_contiguous and flags.writeable:
        entries = values.tolist()
        if (math.isfinite(sum(entries)) or all(map(math.isfinite, entries))) and \
                -HUGE_VALUE <= min(entries) and max(entries) <= HUGE_VALUE:
            return values[None]
    return None


def writeable(values: np.ndarray) -> np.ndarray:
    """``values``, or a copy of it when it is read-only (an
    :class:`~subid.data.IOData` record's arrays are): numba compiles a kernel
    once per combination of argument types, the writeable flag included, so
    the identifiers pass their kernels writeable arrays only and the
    specialisations :mod:`subid.warmup` compiles serve every call instead of
    a second compilation of tens of seconds on the first read-only chunk."""
    return values if values.flags.writeable else values.copy()


def check_stream_grid(T: np.ndarray, dt: float, last_t, who: str, remedy: str) -> None:
    """Raise :class:`DataError` unless the time stamps ``T`` of a chunk (already
    checked: finite, strictly increasing) are the grid of step ``dt`` of an
    identifier created with that period, continuing its stream: uniform with
    step ``dt`` (to :data:`~subid._validation.UNIFORM_RTOL`), and the first
    ``dt`` after ``last_t``, the time of the last sample received (None before
    the first: the first chunk may start anywhere). The one check of
    :class:`~subid.RecursiveSubspace` and :class:`~subid.AdaptiveIdentifier`
    (with ``dt``).

    Parameters
    ----------
    T : ndarray, shape (N,)
    dt : float
        The identifier's sampling period.
    last_t : float or None
    who : str
        The identifier and its period, for the messages
        (``'RecursiveSubspace is discrete-time with dt=0.1'``).
    remedy : str
        What to do about stamps off the grid.
    """
    N = T.shape[0]
    tol = UNIFORM_RTOL * dt
    if N > 1 and np.abs(np.diff(T) - dt).max() > tol * max(1.0, N):
        raise DataError(f"{who}: the time stamps t are not a uniform grid of step dt (steps "
                        f"{float(np.diff(T).min())!r} to {float(np.diff(T).max())!r}); "
                        f"{remedy}")
    if N and last_t is not None:
        expect = last_t + dt
        if abs(T[0] - expect) > tol * max(1.0, abs(expect) / dt):
            raise DataError(f"time stamps t start at {float(T[0])!r}, but the next sample of the "
                            f"stream is due at t = {expect!r} ({who}); the stream must be "
                            f"gap-free and uniformly sampled: {remedy}")


def history_dict(sample, t, A, B, C, D, dt: float) -> dict:
    """The common history format from stacked snapshots (``poles`` computed
    from A: the eigenvalues, continuous-time when ``dt == 0``)."""
    A = np.asarray(A, dtype=float)
    n = A.shape[1] if A.ndim == 3 else 0
    poles = np.array([np.linalg.eigvals(a) for a in A], dtype=complex).reshape(-1, n)
    return {"sample": np.asarray(sample, dtype=np.int64).reshape(-1),
            "t": np.asarray(t, dtype=float).reshape(-1), "poles": poles,
            "A": A, "B": np.asarray(B, dtype=float), "C": np.asarray(C, dtype=float),
            "D": np.asarray(D, dtype=float)}


class OnlineIdentifier(abc.ABC):
    """Base class of the online identifiers (see the module notes for the contract).

    Subclasses implement :meth:`update`, :attr:`model`, :attr:`state`,
    :attr:`n_samples`, :attr:`t`, :attr:`history`, :meth:`save` and
    :meth:`load`, and set ``order``, ``n_inputs`` and ``n_outputs``.
    """

    order: int
    n_inputs: int
    n_outputs: int

    #: Checkpoint format version written by :meth:`save`, and those :meth:`load` reads.
    _VERSION = 1
    _READS: tuple = (1,)
    #: Older checkpoint kinds :meth:`load` still reads.
    _OLD_KINDS: tuple = ()

    @classmethod
    def checkpoint_kind(cls) -> str:
        """The kind written in this class's checkpoints: ``'subid.<Class>'``."""
        return f"subid.{cls.__name__}"

    @classmethod
    def _kinds(cls) -> tuple:
        return (cls.checkpoint_kind(),) + tuple(cls._OLD_KINDS)

    def get_params(self) -> dict:
        """The constructor's settings as given (``selector``: the matrix in use),
        so that ``type(self)(**self.get_params())`` is a fresh identifier with
        the same settings."""
        names = [p for p in inspect.signature(type(self).__init__).parameters if p != "self"]
        return {name: getattr(self, name) for name in names}

    @abc.abstractmethod
    def update(self, u, y=None, t=None) -> "OnlineIdentifier":
        """Add one sample or a chunk (arrays or an IOData record); returns self."""

    @property
    @abc.abstractmethod
    def model(self):
        """The current estimate (a :class:`~subid.model.StateSpace`)."""

    @property
    @abc.abstractmethod
    def state(self) -> np.ndarray:
        """The state estimate at the latest sample."""

    @property
    @abc.abstractmethod
    def n_samples(self) -> int:
        """Samples received so far."""

    @property
    @abc.abstractmethod
    def t(self) -> float | None:
        """Time of the latest sample (None before the first)."""

    @property
    @abc.abstractmethod
    def history(self) -> dict:
        """Bounded snapshots in the common format (module notes)."""

    @abc.abstractmethod
    def save(self, path) -> None:
        """Write the whole state to ``path`` (atomic, no pickle)."""

    @classmethod
    def load(cls, path) -> "OnlineIdentifier":
        """Restore an identifier written by :meth:`save`.

        Each identifier class implements its own ``load``; called on
        :class:`OnlineIdentifier` itself, the class is the one the checkpoint
        names (any subclass whose :meth:`checkpoint_kind`, or an older kind it
        still reads, matches), so ``subid.OnlineIdentifier.load(path)``
        restores whatever identifier was saved there.

        Raises
        ------
        CheckpointError
            Not a checkpoint, or a checkpoint of no identifier class of this
            version of subid.
        """
        from subid.io._checkpoint import load_state
        _, settings = load_state(path, None, None)
        found = settings["_kind"]
        pending, seen = list(cls.__subclasses__()), set()
        while pending:
            sub = pending.pop()
            if sub in seen:
                continue
            seen.add(sub)
            pending.extend(sub.__subclasses__())
            # a class with a load of its own or inherited from an identifier (not this
            # dispatcher): a plain subclass of RecursiveSubspace reads its checkpoints
            dispatcher = getattr(OnlineIdentifier.load, "__func__", None)
            if getattr(sub.load, "__func__", None) is not dispatcher \
                    and found in sub._kinds():
                return sub.load(path)
        raise CheckpointError(f"{path} is a checkpoint of {found[:80]!r}, which no online "
                              f"identifier of this version of subid reads", path=path)

    # -- shared input validation -------------------------------------------
    def _unpack(self, u, y, t):
        """``(u, y, t, record)``: an IOData record unpacked (its explicit time
        stamps as t, if any; ``record`` is the IOData or None). A record without
        time stamps must be sampled with the identifier's ``dt`` (when it has one)."""
        from subid.data import IOData, require_single_experiment
        if isinstance(u, IOData):
            if y is not None or t is not None:
                raise DataError("pass either an IOData record or (u, y[, t]), not both")
            require_single_experiment(u, "an online identifier")
            record = u
            t = record.t if record.has_time_stamps else None
            if t is None and self._dt is not None and not same_period(record.dt, self._dt):
                raise DataError(f"the IOData record is sampled with dt={record.dt!r} but "
                                f"the identifier has dt={self._dt!r}")
            return record.u, record.y, t, record
        if y is None:
            raise DataError("output y is missing: call update(u, y) or update(iodata)")
        return u, y, t, None


# ---------------------------------------------------------------------------
# running an identifier over a record
# ---------------------------------------------------------------------------
def markov_parameters(model, dt_hint=None, count: int = 6, limit: int = 12):
    """Markov parameters h1..h``count`` (impulse-response samples; a
    continuous-time model sampled at ``dt_hint``), at most ``limit``, and
    their names: the parameter trajectories of a convergence plot."""
    m = model
    if m.dt == 0:
        m = m.to_discrete(dt_hint if dt_hint else 1.0)
    h = m.markov(count + 1)[1:]                 # skip D
    names = [f"h{j + 1}({m.output_names[i]}←{m.input_names[q]})"
             for j in range(count) for i in range(m.n_outputs) for q in range(m.n_inputs)]
    values = h.reshape(-1)
    order = np.argsort([j for j in range(count) for _ in range(m.n_outputs * m.n_inputs)],
                       kind="stable")
    return values[order][:limit], [names[i] for i in order][:limit]


def with_names(model, data):
    """``model`` with the channel names of ``data`` (online identifiers name
    their channels u1, y1, ... unless told otherwise)."""
    from subid.model.statespace import StateSpace
    if (tuple(model.input_names), tuple(model.output_names)) == \
            (tuple(data.input_names), tuple(data.output_names)):
        return model
    return StateSpace(model.A, model.B, model.C, model.D, model.dt, K=model.K,
                      noise_cov=model.noise_cov, input_names=data.input_names,
                      output_names=data.output_names, info=model.info, hold=model.hold)


class Tracker:
    """Run an online identifier over a record: snapshots and checkpoints.

    Parameters
    ----------
    ident : OnlineIdentifier
    data : IOData
        The record fed to the identifier.
    fingerprint_data : IOData, optional
        The record whose samples identify a checkpoint's data (default
        ``data``; ``subid track`` passes the raw record before detrending).
    trace_every : int
        Samples between snapshots of the model (0: only at the end).
    checkpoint_every : int
        Samples between checkpoints (0: none during the run).
    checkpoint_dir : str, optional
        Folder of the checkpoints ``checkpoint-<samples>.npz`` and their
        convergence traces ``checkpoint-<samples>.trace.npz``.
    keep : int
        Keep the last ``keep`` checkpoints this tracker wrote (0: all).

    Notes
    -----
    The snapshots hold the poles and the Markov parameters of the model at
    each snapshot (one row per snapshot, bounded by the record length over
    ``trace_every``); :meth:`history` returns them in the format
    :func:`subid.plot.convergence` reads.
    """

    def __init__(self, ident, data, *, fingerprint_data=None, trace_every=0,
                 checkpoint_every=0, checkpoint_dir=None, keep=0):
        self.ident, self.data = ident, data
        self.raw = data if fingerprint_data is None else fingerprint_data
        self.trace_every = int(trace_every)
        self.checkpoint_every = int(checkpoint_every)
        self.checkpoint_dir = checkpoint_dir
        self.keep = int(keep)
        self.samples, self.poles, self.params = [], [], []
        self.names: list[str] = []
        self.written: list[str] = []
        self.dt_hint = data.dt if data.dt is not None else float(np.mean(np.diff(data.t)))

    def run(self, start: int = 0, *, chunk: int = 1000, progress=None) -> None:
        """Feed ``data[start:]`` in chunks of at most ``chunk`` samples, with
        the snapshots and checkpoints due; ``progress(k)`` after each chunk."""
        data = self.data
        n = data.n_samples
        discrete = getattr(self.ident, "dt", None) not in (None, 0, 0.0) \
            and not data.has_time_stamps
        k = start
        while k < n:
            stop = min(n, k + chunk, self.next_stop(k))
            t = None if discrete else data.t[k:stop]
            self.ident.update(data.u[k:stop], data.y[k:stop], t)
            if progress is not None:
                progress(stop - k)
            k = stop
            self(k)
        if start >= n:
            self.snapshot(n)

    def next_stop(self, k: int) -> int:
        stops = [self.data.n_samples]
        for every in (self.trace_every, self.checkpoint_every):
            if every:
                stops.append((k // every + 1) * every)
        return min(stops)

    def __call__(self, k: int) -> None:
        n = self.data.n_samples
        if (self.trace_every and k % self.trace_every == 0) or k == n:
            self.snapshot(k)
        if self.checkpoint_every and self.checkpoint_dir and k % self.checkpoint_every == 0 \
                and k < n:
            self.checkpoint(k)

    def snapshot(self, k: int) -> None:
        """Record the model's poles and Markov parameters at sample ``k`` (no
        snapshot while the identifier has no model yet)."""
        try:
            # intermediate models, for the convergence plot: their warnings (not converged,
            # no stable Kalman predictor yet...) are dropped; the final model's are shown
            # (a noise-free `subid track` printed five predictor warnings differing only
            # in the spectral radius of each snapshot)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = with_names(self.ident.model, self.data)
            poles = model.poles()
            values, names = markov_parameters(model, self.dt_hint)
        except SubidError:
            return
        if self.samples and self.samples[-1] == k:
            return
        self.samples.append(k)
        self.poles.append(poles)
        self.params.append(values)
        self.names = names

    def history(self) -> dict:
        """``sample``, ``poles``, ``parameters``, ``parameter_names`` of the
        snapshots (:func:`subid.plot.convergence`)."""
        if not self.samples:
            return {"sample": np.zeros(0, dtype=np.int64), "poles": np.zeros((0, 0), complex)}
        return {"sample": np.array(self.samples), "poles": np.array(self.poles),
                "parameters": np.array(self.params), "parameter_names": list(self.names)}

    def fingerprint(self, k: int) -> str:
        """Hash of the first ``k`` samples of the record (which data a checkpoint saw)."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.raw.u[:k]).tobytes())
        h.update(np.ascontiguousarray(self.raw.y[:k]).tobytes())
        return h.hexdigest()

    def save_trace(self, path, k: int) -> None:
        """Write the snapshots and the data fingerprint (atomic ``.npz``)."""
        from subid.io._files import atomic_write
        hist = self.history()
        arrays = {"sample": np.asarray(hist["sample"], dtype=np.int64),
                  "poles_re": np.asarray(hist["poles"]).real,
                  "poles_im": np.asarray(hist["poles"]).imag,
                  "parameters": np.asarray(hist.get("parameters", np.zeros((0, 0)))),
                  "parameter_names": np.array(hist.get("parameter_names", []), dtype=str),
                  "fingerprint": np.array(self.fingerprint(k)),
                  "method": np.array(type(self.ident).__name__)}
        # the offsets removed from the record fed (none: shape (0,)), for a resumed
        # run to remove the same ones (absent in the traces of earlier versions)
        for name in ("u_offset", "y_offset"):
            value = getattr(self.data, name, None)
            arrays[name] = np.zeros(0) if value is None else np.asarray(value, dtype=float)
        with atomic_write(path, "wb", what="convergence trace") as fh:
            np.savez(fh, **arrays)  # type: ignore[arg-type]  # numpy's stub: **kwds may be allow_pickle

    @staticmethod
    def trace_path(checkpoint) -> str:
        """The convergence trace written beside the checkpoint ``checkpoint``."""
        checkpoint = os.fspath(checkpoint)
        return (checkpoint[:-4] if checkpoint.endswith(".npz") else checkpoint) + ".trace.npz"

    @staticmethod
    def stored_offsets(path):
        """``(u_offset, y_offset)`` removed from the record of the run that wrote the
        trace ``path`` (arrays of shape (0,) when it removed none), or None when the
        trace is missing, unreadable or older than these fields."""
        from subid.io._files import open_regular
        from subid.io._npz import load_npz
        try:
            fh, size = open_regular(path, what="convergence trace")
            with fh:
                z = load_npz(fh, size=size)
            offsets = tuple(np.asarray(z[name], dtype=float) for name in ("u_offset", "y_offset"))
        except Exception:            # noqa: BLE001 - missing, unreadable, older: unknown offsets
            return None
        return offsets if all(np.isfinite(o).all() for o in offsets) else None

    def load_trace(self, path, k: int) -> None:
        """Continue the snapshots of a checkpoint's trace (up to sample ``k``).

        A missing or unreadable trace, or one made on other data, is reported
        by a :class:`UserWarning`; the snapshots then start at ``k``."""
        if not os.path.exists(path):
            warnings.warn(f"no convergence trace next to the checkpoint ({path}); the "
                          f"convergence plot starts at sample {k}", UserWarning, stacklevel=2)
            return
        from subid.io._files import open_regular
        from subid.io._npz import load_npz
        try:
            fh, size = open_regular(path, what="convergence trace")
            with fh:
                z = load_npz(fh, size=size)
            sample = z["sample"]
            poles = z["poles_re"] + 1j * z["poles_im"]
            params = z["parameters"]
            names = [str(s) for s in z["parameter_names"]]
            fingerprint = str(z["fingerprint"])
        except Exception as exc:     # noqa: BLE001 - SubidError, NpzError, KeyError, dtype: a new trace
            warnings.warn(f"convergence trace {path} unreadable ({exc}); starting a new one",
                          UserWarning, stacklevel=2)
            return
        if fingerprint != self.fingerprint(k):
            warnings.warn(f"the checkpoint was made on other data: the first {k} samples of "
                          "this record differ from those the identifier has seen",
                          UserWarning, stacklevel=2)
        keep = sample <= k
        self.samples = [int(s) for s in sample[keep]]
        self.poles = list(poles[keep])
        self.params = list(params[keep]) if params.ndim == 2 and params.shape[0] == keep.size \
            else []
        if len(self.params) != len(self.samples):
            self.samples, self.poles, self.params = [], [], []
        self.names = names

    def checkpoint(self, k: int) -> str:
        """Save the identifier and its trace as ``checkpoint-<k>.npz``; prune
        this tracker's older checkpoints beyond ``keep``. Returns the path."""
        from subid.io._files import made_folders
        path = os.path.join(self.checkpoint_dir, f"checkpoint-{k:010d}.npz")
        with made_folders(self.checkpoint_dir):          # no empty folder after a failure
            self.save_trace(path[:-4] + ".trace.npz", k)
            try:
                self.ident.save(path)
            except BaseException:
                with contextlib.suppress(OSError):
                    os.unlink(path[:-4] + ".trace.npz")
                raise
        self.written.append(path)
        if self.keep:
            # Prune only the checkpoints this run wrote, oldest first (never by
            # sorting the names in the folder: those of an earlier run on a
            # longer record would sort after this run's and survive, and this
            # run's newest would be deleted).
            while len(self.written) > self.keep:
                old = self.written.pop(0)
                if old == path:
                    continue
                for name in (old, old[:-4] + ".trace.npz"):
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(name)
        return path
