"""Exchange with MATLAB (``.mat`` files), pandas, python-control and scipy:
``import subid.interop``.

The public name of :mod:`subid.io.interop`, where the converters are
documented (MATLAB's ``ss(A, B, C, D, Ts)`` fields; DataFrames with one
column per channel; converted model files and Python scripts, the library
side of ``subid convert``). pandas is imported only when a pandas converter
is called.
"""

from subid.io.interop import (
    CONVERT_TARGETS,
    convert_model,
    iodata_from_pandas,
    iodata_to_pandas,
    load_mat,
    operating_point,
    python_source,
    save_mat,
)

__all__ = ["save_mat", "load_mat", "iodata_from_pandas", "iodata_to_pandas", "convert_model",
           "python_source", "operating_point", "CONVERT_TARGETS"]
