"""Files: readers and writers of records and models (CSV, NPZ, MAT, JSON), checkpoints, and interoperability with python-control, scipy and pandas."""

from subid.io.formats import read, read_chunks

__all__ = ['read', 'read_chunks']
