"""The version of subid: the one place it is written.

Read by ``pyproject.toml`` (``[tool.setuptools.dynamic]``), ``subid.__version__``,
``subid --version``, the reports and the JSON model files (``subid_version``).
"""

__version__ = "0.1.0"
