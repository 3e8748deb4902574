"""Code habits checked as tests (issue 13): ruff, the import graph, docstring parameters.

These read the source as text (ast); they import nothing of subid.
"""

from __future__ import annotations

import ast
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "subid"

# Edges the import-graph test tolerates until the method registry (issue 13, item 1) moves
# the method table out of the command line: the demo still reads ``cli.METHODS``.
PENDING_EDGES: set = set()


# ---------------------------------------------------------------------------
# ruff: pyflakes (F), import order (I), bugbear (B); configured in pyproject.toml
# ---------------------------------------------------------------------------
def test_ruff_reports_nothing():
    pytest.importorskip("ruff")
    proc = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "src", "tests",
                           "bench", "docs", "examples"], cwd=ROOT, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


# ---------------------------------------------------------------------------
# import graph
# ---------------------------------------------------------------------------
def _modules() -> dict[str, tuple[pathlib.Path, bool]]:
    out = {}
    for path in SRC.rglob("*.py"):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        out[".".join(parts)] = (path, is_package)
    return out


def _is_main_guard(node) -> bool:
    """``if __name__ == "__main__":``: runs when the file is a script, not on import."""
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Compare) and isinstance(test.left, ast.Name)
            and test.left.id == "__name__" and len(test.comparators) == 1
            and isinstance(test.comparators[0], ast.Constant)
            and test.comparators[0].value == "__main__")


def _imports(tree):
    """Every import statement, at module level and inside functions (lazy imports
    count: a cycle through a function is a cycle of the design), except those under
    a ``__main__`` guard."""
    for node in ast.iter_child_nodes(tree):
        if _is_main_guard(node):
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        else:
            yield from _imports(node)


def import_graph() -> dict[str, set[str]]:
    """``{module: modules of subid it imports}`` for every module of src/subid."""
    modules = _modules()
    graph = {name: set() for name in modules}
    for name, (path, is_package) in modules.items():
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            else:
                if node.level:
                    base = name.split(".") if is_package else name.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module
                # ``from pkg import mod`` imports the submodule pkg.mod
                targets = [base] + [f"{base}.{alias.name}" for alias in node.names]
            graph[name].update(t for t in targets if t in modules and t != name)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_import_graph_has_the_known_edges():
    graph = import_graph()
    assert "subid.data" in graph["subid.io.formats"]             # from .data import IOData
    assert "subid.model.statespace" in graph["subid.io.interop"]
    assert "subid.methods.online._adaptive_kernel" in graph["subid.methods.online.adaptive"]   # from . import x
    assert "subid.model.statespace" in graph["subid.experiments.seed001"] or \
        "subid.systems" in graph["subid.experiments.seed001"]    # relative level 2


def test_no_import_cycles():
    graph = import_graph()
    for a, b in PENDING_EDGES:
        graph[a].discard(b)
    found = cycles(graph)
    detail = "; ".join(" <-> ".join(c) + " (" + ", ".join(
        f"{a} -> {b}" for a in c for b in sorted(graph[a] & set(c))) + ")" for c in found)
    assert not found, f"import cycles: {detail}"


def test_command_line_uses_no_private_helper_of_other_modules():
    """The CLI calls the library's public functions (``io.read_inputs``,
    ``report.comparison_page``), not ``sio._Table`` or ``report._page``."""
    private = re.compile(r"\b(?:sio|io|report|plot|demo|metrics|model|data)\._[a-z]\w*")
    for module in sorted(str(p.relative_to(SRC)) for p in (SRC / "cli").rglob("*.py")):
        # private attributes used in code (a private module's public names, imported
        # with ``from subid.io._files import atomic_write``, are fine)
        text = "\n".join(line for line in (SRC / module).read_text(encoding="utf-8").splitlines()
                          if not line.lstrip().startswith(("from ", "import ")))
        assert not private.findall(text), (module, private.findall(text))


# ---------------------------------------------------------------------------
# numpydoc: documented parameters match the signature
# ---------------------------------------------------------------------------
_DASHES = re.compile(r"\s*-{3,}\s*")


def documented_parameters(doc: str) -> list[str]:
    """Names in the ``Parameters`` (and ``Other Parameters``) sections, in order;
    ``a, b : int`` gives both names."""
    lines = doc.expandtabs().splitlines()
    names, i = [], 0
    while i < len(lines) - 1:
        if lines[i].strip() in ("Parameters", "Other Parameters") \
                and _DASHES.fullmatch(lines[i + 1]):
            indent = len(lines[i]) - len(lines[i].lstrip())
            j = i + 2
            while j < len(lines):
                line = lines[j]
                if line.strip() and len(line) - len(line.lstrip()) == indent:
                    if j + 1 < len(lines) and _DASHES.fullmatch(lines[j + 1]):
                        break                               # the next section
                    names += [n.strip().lstrip("\\") for n in line.split(":")[0].split(",")
                              if n.strip()]
                j += 1
            i = j
        else:
            i += 1
    return names


def _signature(args: ast.arguments, *, method: bool) -> list[str]:
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    if method and names and names[0] in ("self", "cls"):
        names = names[1:]
    if args.vararg:
        names.append("*" + args.vararg.arg)
    if args.kwarg:
        names.append("**" + args.kwarg.arg)
    return names


def docstring_mismatches() -> list[str]:
    """Public functions, methods and classes (``__init__``) of the public modules
    whose ``Parameters`` section differs from the signature (names or order)."""
    problems = []

    def check(doc, args, where, method):
        documented = documented_parameters(doc or "")
        if documented and documented != _signature(args, method=method):
            problems.append(f"{where}: documented {documented}, signature "
                            f"{_signature(args, method=method)}")

    def visit(body, prefix, path, in_class):
        for node in body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                init = [n for n in node.body
                        if isinstance(n, ast.FunctionDef) and n.name == "__init__"]
                if init:
                    check(ast.get_docstring(node), init[0].args,
                          f"{path}:{node.lineno} {prefix}{node.name}", True)
                visit(node.body, f"{prefix}{node.name}.", path, True)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) \
                    and not node.name.startswith("_"):
                check(ast.get_docstring(node), node.args,
                      f"{path}:{node.lineno} {prefix}{node.name}", in_class)

    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC)
        if any(part.startswith("_") and part != "__init__.py" for part in rel.parts):
            continue                                        # private modules
        visit(ast.parse(path.read_text(encoding="utf-8")).body, "", rel, False)
    return problems


def test_documented_parameters_parser():
    doc = """Summary.

    Parameters
    ----------
    a, b : int
        Two.
    \\*args
        More.
    c : {'x', 'y'}

    Returns
    -------
    d : float
    """
    assert documented_parameters(doc) == ["a", "b", "*args", "c"]


def test_documented_parameters_match_signatures():
    problems = docstring_mismatches()
    assert not problems, "\n".join(problems)


# ---------------------------------------------------------------------------
# every file writer goes through the atomic writer (subid.io._files)
# ---------------------------------------------------------------------------
_WRITERS = {"savefig", "savez", "savez_compressed", "save", "savetxt", "savemat", "dump",
            "write_text", "write_bytes", "to_csv", "to_parquet", "to_json"}
# writers that are module functions (``json.dump``, ``np.save``), not methods of our
# own objects (``StateSpace.save`` writes atomically itself)
_RECEIVERS = {"dump": "json", "save": "np", "savez": "np", "savez_compressed": "np",
              "savetxt": "np"}
# in-memory or temporary targets, not user files: (module, function)
_NOT_FILES = {("evaluation/report.py", "figure_html"),        # PNG into a BytesIO
              ("io/_files.py", "write_json"), ("io/_files.py", "save_figure"),
              ("io/_files.py", "write_bytes")}


def unsafe_writes() -> list[str]:
    """Writes to files outside a ``with atomic_write(...)`` block."""
    found = []

    def is_atomic(item: ast.withitem) -> bool:
        call = item.context_expr
        return isinstance(call, ast.Call) and getattr(call.func, "id", getattr(
            call.func, "attr", None)) in ("atomic_write", "atomic_directory")

    def visit(node, rel, function, inside):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            function = node.name
        if isinstance(node, (ast.With, ast.AsyncWith)) and any(map(is_atomic, node.items)):
            inside = True
        if isinstance(node, ast.Call) and not inside and (rel, function) not in _NOT_FILES:
            name = getattr(node.func, "id", getattr(node.func, "attr", None))
            if name == "open" and isinstance(node.func, ast.Name):
                mode = node.args[1] if len(node.args) > 1 else next(
                    (k.value for k in node.keywords if k.arg == "mode"), None)
                if isinstance(mode, ast.Constant) and set(str(mode.value)) & set("wax+"):
                    found.append(f"{rel}:{node.lineno} open(..., {mode.value!r})")
            elif name in _WRITERS and isinstance(node.func, ast.Attribute) and _RECEIVERS.get(
                    name, getattr(node.func.value, "id", "")) == getattr(
                    node.func.value, "id", ""):
                found.append(f"{rel}:{node.lineno} .{name}(...)")
        for child in ast.iter_child_nodes(node):
            visit(child, rel, function, inside)

    for path in sorted(SRC.rglob("*.py")):
        rel = str(path.relative_to(SRC))
        visit(ast.parse(path.read_text(encoding="utf-8")), rel, None, False)
    return found


def test_every_writer_is_atomic():
    assert not unsafe_writes(), unsafe_writes()


# ---------------------------------------------------------------------------
# numba kernels are cached on disk (issue 13, item 5)
# ---------------------------------------------------------------------------
def test_every_numba_kernel_is_cached():
    """``@numba.njit(cache=True, ...)``: a second process loads the compiled
    kernel instead of compiling it again."""
    uncached, count = [], 0
    for path in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for deco in node.decorator_list:
                target = deco.func if isinstance(deco, ast.Call) else deco
                name = getattr(target, "attr", getattr(target, "id", ""))
                if name not in ("njit", "jit", "vectorize", "guvectorize"):
                    continue
                count += 1
                cached = isinstance(deco, ast.Call) and any(
                    k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value
                    is True for k in deco.keywords)
                if not cached:
                    uncached.append(f"{path.relative_to(SRC)}:{node.lineno} {node.name}")
    assert count >= 10                     # the scan sees the kernels
    assert not uncached, uncached
