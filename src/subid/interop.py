"""Exchange with MATLAB (``.mat`` files) and pandas: ``import subid.interop``.

The public name of :mod:`subid.io.interop`, where the converters are
documented (MATLAB's ``ss(A, B, C, D, Ts)`` fields; DataFrames with one
column per channel). pandas is imported only when a pandas converter is
called.
"""

from subid.io.interop import iodata_from_pandas, iodata_to_pandas, load_mat, save_mat

__all__ = ["save_mat", "load_mat", "iodata_from_pandas", "iodata_to_pandas"]
