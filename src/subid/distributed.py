"""Identification on Dask clusters: ``import subid.distributed``.

The public name of :mod:`subid.methods.dt.distributed`, where the functions
are implemented and documented (per-chunk Hankel statistics merged exactly
on the workers). Dask is optional: install the ``distributed`` extra
(``pip install ".[distributed]"`` in the subid source folder); it is
imported when a function runs, not by this import.
"""

from subid.methods.dt.distributed import (
    fan_out,
    identify,
    identify_files,
    identify_many,
    summary_markdown,
)

__all__ = ["identify", "identify_files", "fan_out", "identify_many", "summary_markdown"]
