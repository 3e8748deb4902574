"""Frequency units of frequency-response files, converted to radians per time unit.

One table for the header of a text file (``Frequency [kHz]``) and MATLAB's
``FrequencyUnit`` property of an ``idfrd``/``frd`` saved to a ``.mat`` file.
The time unit of the data (of ``dt``) is taken to be the second, except for
the units relative to it (``rad/TimeUnit``, ``cycles/TimeUnit``, and a bare
``rad``), which need no conversion; :func:`frequency_factor` takes the
seconds per time unit when the file states the time unit (MATLAB's
``TimeUnit``).
"""

from __future__ import annotations

import math
import re

__all__ = ["frequency_factor", "seconds_per", "KNOWN_UNITS"]

_SECONDS = {
    "ns": 1e-9, "nanosecond": 1e-9, "nanoseconds": 1e-9,
    "us": 1e-6, "µs": 1e-6, "microsecond": 1e-6, "microseconds": 1e-6,
    "ms": 1e-3, "msec": 1e-3, "millisecond": 1e-3, "milliseconds": 1e-3,
    "s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0,
    "min": 60.0, "minute": 60.0, "minutes": 60.0,
    "h": 3600.0, "hr": 3600.0, "hour": 3600.0, "hours": 3600.0,
    "d": 86400.0, "day": 86400.0, "days": 86400.0,
    "wk": 604800.0, "week": 604800.0, "weeks": 604800.0,
}
_CALENDAR = {"month", "months", "mo", "year", "years", "yr", "y"}
_HZ_PREFIX = {"": 1.0, "k": 1e3, "K": 1e3, "M": 1e6, "G": 1e9}
_PER_RE = re.compile(r"^(?P<angle>rad|rads|radian|radians|cycle|cycles|cyc|rev|revs|"
                     r"revolution|revolutions)\s*(?:/|per\s)\s*(?P<time>.+)$")

#: The units, as said in error messages.
KNOWN_UNITS = ("rad/s (rad/TimeUnit, rad/ms, rad/min, rad/hr, ...), Hz (cycles/TimeUnit, "
               "kHz, MHz, GHz, mHz, cycles/min, ...), rpm")


def seconds_per(time_unit: str) -> float | None:
    """Seconds in one ``time_unit`` (``'ms'``, ``'minutes'``, ...), or None if unknown."""
    return _SECONDS.get(time_unit.strip().lower())


def frequency_factor(unit: str, seconds_per_time_unit: float = 1.0) -> float | None:
    """The factor from ``unit`` to radians per time unit, or None if the unit is unknown.

    Parameters
    ----------
    unit : str
        ``'rad/s'``, ``'Hz'``, ``'kHz'``, ``'MHz'``, ``'GHz'``, ``'mHz'``,
        ``'rpm'``, ``'rad/<time>'``, ``'cycles/<time>'`` with ``<time>`` one of
        ``ns``, ``us``, ``ms``, ``s``, ``min``, ``hr``, ``day``, ``week`` (or
        spelt out, singular or plural), or ``'rad/TimeUnit'``,
        ``'cycles/TimeUnit'`` (relative to the data's time unit). Case is
        ignored except in the prefix of Hz: ``MHz`` is 1e6 Hz and ``mHz``
        1e-3 Hz (``mhz`` is ambiguous and unknown). Months and years have no
        fixed length and are unknown.
    seconds_per_time_unit : float
        Seconds in the data's time unit (1: the time unit is the second).

    Returns
    -------
    float or None
    """
    text = unit.strip()
    if text[-2:].lower() == "hz":
        prefix = text[:-2].strip()
        if prefix == "m":
            scale = 1e-3 if text[-2:] == "Hz" else None       # mHz; 'mhz' is ambiguous
        else:
            scale = _HZ_PREFIX.get(prefix)
        return None if scale is None else 2 * math.pi * scale * seconds_per_time_unit
    low = text.lower()
    if low in ("rad", "radian", "radians"):
        return 1.0
    if low == "rpm":
        return 2 * math.pi / 60.0 * seconds_per_time_unit
    match = _PER_RE.match(low)
    if match is None:
        return None
    angle = 1.0 if match.group("angle").startswith("rad") else 2 * math.pi
    time = match.group("time").strip()
    if time in ("timeunit", "time unit"):
        return angle
    if time in _CALENDAR:
        return None
    seconds = _SECONDS.get(time)
    return None if seconds is None else angle / seconds * seconds_per_time_unit
