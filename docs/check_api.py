"""Check that every name in ``subid.__all__`` has an entry in the built API reference.

Usage: ``python docs/check_api.py SITE_DIR`` after ``mkdocs build``. An entry is the
anchor that mkdocstrings gives an object's heading, ``id="MODULE.QUALNAME"`` with the
object's canonical path (``subid.ls_subspace.ls_subspace`` for ``subid.ls_subspace``: the
function shares its name with its module), or the module's name for a module; the
paths are read from the imports of ``subid/__init__.py``. Exit
status 1, with the missing names, when one is absent.
"""

import ast
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def exported_names() -> dict[str, str]:
    """``{name: canonical path}`` for ``subid.__all__``, read from ``subid/__init__.py``
    without importing it (the docs environment has only the documentation tools):
    ``from . import mod`` gives ``subid.mod``, ``from .mod import name`` gives
    ``subid.mod.name``, and so do the entries of the lazy-import table ``_LAZY``."""
    tree = ast.parse((ROOT / "src" / "subid" / "__init__.py").read_text())
    where, names = {}, None
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            for alias in node.names:
                key = alias.asname or alias.name
                where[key] = (f"subid.{node.module}.{alias.name}" if node.module
                              else f"subid.{alias.name}")
        elif isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            names = [ast.literal_eval(elt) for elt in node.value.elts]
        elif isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets):
            # lazy public names (PEP 562): {name: (module, attribute or None)}
            for name, (module, attr) in ast.literal_eval(node.value).items():
                where[name] = f"subid.{module}.{attr}" if attr else f"subid.{module}"
    if names is None:
        raise SystemExit("subid/__init__.py has no __all__")
    unknown = [n for n in names if n not in where]
    if unknown:
        raise SystemExit("names in __all__ not imported in subid/__init__.py: "
                         + ", ".join(unknown))
    return {n: where[n] for n in names}


def main(site: str) -> int:
    pages = sorted((pathlib.Path(site) / "api").rglob("*.html"))
    if not pages:
        print(f"no API pages under {site}/api: build the site first", file=sys.stderr)
        return 1
    html = "\n".join(p.read_text(encoding="utf-8") for p in pages)
    names = exported_names()
    missing = [n for n, path in names.items() if f'id="{path}"' not in html]
    if missing:
        print("not in the API reference: " + ", ".join(missing), file=sys.stderr)
        return 1
    print(f"API reference: all {len(names)} names of subid.__all__ documented")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "site"))
