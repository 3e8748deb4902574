"""The layers of src/subid, checked as a test (issue 24, item 3).

The flow is data -> statistic -> model -> (io) -> methods -> evaluation -> command line: a
package imports the packages listed for it in ``ALLOWED`` and nothing else, lazy imports
inside functions included, and never another package's private module (``_name``) unless
``PRIVATE_ALLOWED`` lists the pair with its reason. Every listed edge must exist (a stale
entry fails too), so the lists say what the code does. Read as text (ast), like the
import-cycle test of test_style.py; nothing of subid is imported.
"""

from __future__ import annotations

import ast

from test_style import SRC, _imports, _modules

# Top-level private modules every package may use: the package's own utilities.
FOUNDATION = {"_version", "errors", "_validation", "_repr", "_extras", "_threads", "_progress",
              "_kernel_args", "_blas"}

# Public aliases at the top of the package (``subid.plot`` is ``subid.evaluation.plot``...).
ALIASES = {"basis": "methods", "registry": "methods", "distributed": "methods",
           "interop": "io", "plot": "evaluation", "__main__": "cli"}

# node -> the nodes it may import ("foundation" is FOUNDATION; "subid" the package itself,
# whose lazy table reaches everything: only the top layers may import it).
ALLOWED = {
    "foundation": set(),
    "config": {"foundation"},
    "data": {"foundation"},
    "frdata": {"foundation"},
    "delay": {"foundation", "data"},
    "datasets": {"foundation", "data"},
    "statistic": {"foundation", "data"},
    # model: simulation, prediction and the fit (NRMSE %) of a model on records and
    # frequency responses (model.fit), below the methods that score candidates with them
    "model": {"foundation", "data", "frdata", "delay"},
    "systems": {"foundation", "data", "model"},
    # io reads records and writes models: below the methods that stream files and
    # checkpoint (methods.dt.stream, methods.online.base), above the model.
    "io": {"foundation", "data", "frdata", "delay", "model"},
    "methods": {"foundation", "data", "frdata", "delay", "statistic", "model", "io"},
    "evaluation": {"foundation", "data", "frdata", "delay", "model", "io", "methods",
                   "subid"},                          # report: subid.__version__
    "cli": {"foundation", "data", "datasets", "model", "io", "methods", "evaluation",
            "warmup", "subid"},
    "experiments": {"foundation", "data", "systems", "model", "io", "methods", "evaluation",
                    "subid"},
    "warmup": {"foundation", "data", "systems", "statistic", "model", "methods"},
    # the public contract checks of methods (scikit-learn's check_estimator)
    "testing": {"foundation", "data", "frdata", "systems", "model", "methods", "evaluation"},
    "subid": {"foundation"},
}

# (importer prefix, private module): allowed imports of another package's private module.
PRIVATE_ALLOWED = {
    # Whether numba's cache holds three kernels of the default calls (warmup.kernels_cached).
    ("subid.warmup", "subid.model._simulate"),
    ("subid.warmup", "subid.model._sensitivity"),
    ("subid.warmup", "subid.methods.dt._lag_kernel"),
    # The atomic writer: every file goes through it (test_style.test_every_writer_is_atomic).
    ("subid.cli", "subid.io._files"),
    ("subid.evaluation.report", "subid.io._files"),
    ("subid.experiments", "subid.io._files"),
    ("subid.methods.online.base", "subid.io._files"),
    # Checkpoint files of the online identifiers (their save/load contract).
    ("subid.methods.online", "subid.io._checkpoint"),
    ("subid.methods.online.base", "subid.io._npz"),
    # The simulation kernels of the model (state recursion, matrix exponentials).
    ("subid.methods", "subid.model._simulate"),
    # The sensitivity recursion of a state-space system (pem's Jacobian, the bands).
    ("subid.methods.dt", "subid.model._sensitivity"),
    ("subid.evaluation.uncertainty", "subid.model._sensitivity"),
    # The Hankel factor type of the statistic.
    ("subid.methods", "subid.statistic._hankel"),
    # The lagged statistics of RecursiveSubspace's exact B, D regression build its normal
    # equations in the batch regression's parameter layout (_regression.parameter_count);
    # the recursive identifier itself reaches B, D, x0 through methods.bd.fit_b_d_x0 only.
    ("subid.methods.online._lagged", "subid.methods.dt._regression"),
    # The one B, D, x0 entry point dispatches to its engines (issue 24 item 2).
    ("subid.methods.bd", "subid.methods.dt._regression"),
    ("subid.methods.bd", "subid.methods.dt._bd_large"),
    ("subid.methods.bd", "subid.methods.dt._residual_bound"),
    ("subid.methods.bd", "subid.methods.ct._ct_fit"),
    ("subid.methods.bd", "subid.methods.ct._ct_estimate"),
}


def node(module: str) -> str:
    """The layer node of a module: its top-level package or module under subid."""
    parts = module.split(".")
    if len(parts) == 1:
        return "subid"
    top = parts[1]
    if top in FOUNDATION:
        return "foundation"
    return ALIASES.get(top, top)


def edges() -> dict[str, set[str]]:
    """``{module: modules of subid it imports}``; ``from subid import _threads`` is an
    edge to ``subid._threads`` only, not to the package ``subid``."""
    modules = _modules()
    graph = {name: set() for name in modules}
    for name, (path, is_package) in modules.items():
        for stmt in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(stmt, ast.Import):
                graph[name].update(a.name for a in stmt.names if a.name in modules)
                continue
            if stmt.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[:len(base) - (stmt.level - 1)]
                base = ".".join(base + ([stmt.module] if stmt.module else []))
            else:
                base = stmt.module
            submodules = [f"{base}.{a.name}" for a in stmt.names if f"{base}.{a.name}" in modules]
            graph[name].update(submodules)
            if len(submodules) < len(stmt.names) and base in modules:
                graph[name].add(base)                       # names of the module itself
            graph[name].discard(name)
    return graph


def private_owner(module: str) -> str | None:
    """The package a private module belongs to: ``subid.io`` for ``subid.io._files``,
    ``subid.methods.dt`` for ``subid.methods.dt._subspace`` (the subpackages of methods
    keep their private modules to themselves); None for a public module or one of the
    package's own utilities (``subid._validation``)."""
    parts = module.split(".")
    for i, part in enumerate(parts[1:], 1):
        if part.startswith("_") and not part.startswith("__"):
            if i == 1:
                return None
            owner = parts[:i]
            return ".".join(owner if owner[1] == "methods" else owner[:2])
    return None


def package_edges() -> dict[tuple[str, str], list[str]]:
    out: dict[tuple[str, str], list[str]] = {}
    for a, targets in edges().items():
        for b in targets:
            if node(a) != node(b):
                out.setdefault((node(a), node(b)), []).append(f"{a} -> {b}")
    return out


def private_imports() -> list[tuple[str, str]]:
    found = []
    for a, targets in edges().items():
        for b in targets:
            owner = private_owner(b)
            if owner is not None and a != owner and not a.startswith(owner + "."):
                found.append((a, b))
    return sorted(found)


def _allowed_private(a: str, b: str) -> tuple[str, str] | None:
    for prefix, target in PRIVATE_ALLOWED:
        if b == target and (a == prefix or a.startswith(prefix + ".")):
            return prefix, target
    return None


def test_node_and_owner():
    assert node("subid.io._files") == "io" and node("subid._validation") == "foundation"
    assert node("subid.plot") == "evaluation" and node("subid") == "subid"
    assert private_owner("subid.io._files") == "subid.io"
    assert private_owner("subid.methods.dt._subspace") == "subid.methods.dt"
    assert private_owner("subid.methods._common") == "subid.methods"
    assert private_owner("subid.evaluation.figures._common") == "subid.evaluation"
    assert private_owner("subid._validation") is None
    assert private_owner("subid.io.formats") is None


def test_the_scan_sees_the_known_edges():
    graph = edges()
    assert "subid.data" in graph["subid.io.text"]
    assert "subid.io._files" in graph["subid.io.models"]
    assert "subid._threads" in graph["subid.io.fast_csv"]
    assert "subid" not in graph["subid.io.fast_csv"]          # from subid import _threads
    assert ("io", "model") in package_edges()


def test_every_package_edge_is_allowed():
    found = package_edges()
    extra = {k: v for k, v in found.items() if k[1] not in ALLOWED.get(k[0], set())}
    assert not extra, "imports across layers not in ALLOWED: " + "; ".join(
        f"{a} -> {b} ({', '.join(v[:3])})" for (a, b), v in sorted(extra.items()))


def test_every_allowed_edge_exists():
    found = package_edges()
    stale = [(a, b) for a, targets in ALLOWED.items() for b in targets if (a, b) not in found]
    assert not stale, f"ALLOWED lists edges the code no longer has: {stale}"


def test_no_private_module_of_another_package():
    bad = [f"{a} -> {b}" for a, b in private_imports() if _allowed_private(a, b) is None]
    assert not bad, "private modules of another package: " + ", ".join(bad)


def test_every_allowed_private_import_exists():
    used = {_allowed_private(a, b) for a, b in private_imports()}
    stale = sorted(PRIVATE_ALLOWED - used)
    assert not stale, f"PRIVATE_ALLOWED lists imports the code no longer has: {stale}"


def test_model_imports_no_io():
    graph = edges()
    leaks = [f"{a} -> {b}" for a, targets in graph.items() if node(a) == "model"
             for b in targets if node(b) == "io"]
    assert not leaks, leaks


def test_evaluation_and_cli_use_no_private_method_module():
    leaks = [f"{a} -> {b}" for a, b in private_imports()
             if node(a) in ("evaluation", "cli") and node(b) == "methods"]
    assert not leaks, leaks


def test_no_command_module_imports_another():
    """The command line: each command in its own module on cli/_shared.py; only
    commands.py (the entry point) imports the command modules, and the demo job
    (cli/demo.py) imports none of them."""
    graph = edges()
    shared = {"subid.cli._shared", "subid.cli.commands", "subid.cli"}
    for a, targets in graph.items():
        if a.startswith("subid.cli.") and a not in ("subid.cli.commands",):
            inner = {b for b in targets if b.startswith("subid.cli") and b not in shared}
            inner.discard("subid.cli.demo")                 # the job behind subid demo
            assert not inner, (a, inner)
        if a == "subid.cli.demo":
            assert not {b for b in targets if b.startswith("subid.cli")}, targets


def test_modules_are_under_1000_lines():
    """One concern per module (issue 24, item 4); compiled-kernel modules (numba) up to
    1,500 lines."""
    long = []
    for path in sorted(SRC.rglob("*.py")):
        lines = path.read_text(encoding="utf-8").count("\n")
        limit = 1500 if "numba" in path.read_text(encoding="utf-8") and \
            path.name.startswith("_") and "kernel" in path.name else 1000
        if lines > limit:
            long.append(f"{path.relative_to(SRC)}: {lines}")
    assert not long, long
