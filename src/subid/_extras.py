"""How to install an optional dependency, in one phrase for error messages.

subid is not published on a package index: it is installed from its source
folder (``pip install ".[plot]"``, as ``make demo`` does), so a message about a
missing optional package names the extra of ``pyproject.toml`` that brings it,
with the command that works from the source folder, and the plain package
that works anywhere.
"""

from __future__ import annotations

__all__ = ["install_hint"]


def install_hint(extra: str, package: str) -> str:
    """``install the '{extra}' extra (pip install ".[{extra}]" in the subid source folder,
    or pip install {package})``.

    Parameters
    ----------
    extra : str
        An extra of ``pyproject.toml`` (``'plot'``, ``'control'``, ...).
    package : str
        The package the extra brings, as ``pip install`` names it.
    """
    return (f"install the '{extra}' extra (pip install \".[{extra}]\" in the subid source "
            f"folder, or pip install {package})")
