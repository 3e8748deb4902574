"""``import subid`` is lazy (PEP 562): every public name still works."""

import importlib
import subprocess
import sys
import types

import subid

HEAVY = ("numba", "scipy.optimize", "matplotlib", "dask", "pandas")


def _fresh(code):
    """Run ``code`` in a new interpreter (same sys.path) and return its stdout."""
    env_path = ":".join(p for p in sys.path if p)
    out = subprocess.run(
        [sys.executable, "-c", f"import sys; sys.path[:0] = {env_path.split(':')!r}\n" + code],
        capture_output=True, text=True, check=True,
    )
    return out.stdout


def test_every_public_name_resolves_to_the_object_in_its_module():
    for name in subid.__all__:
        module_name, attribute = subid._LAZY[name]
        module = importlib.import_module(f"subid.{module_name}")
        expected = module if attribute is None else getattr(module, attribute)
        assert getattr(subid, name) is expected, name


def test_from_import_star_and_dir_list_the_public_names():
    namespace = {}
    exec("from subid import *", namespace)
    assert set(subid.__all__) <= set(namespace)
    assert set(subid.__all__) <= set(dir(subid))
    # the package's own helpers (the importlib it loads names with) are not public names
    assert not [name for name in dir(subid)
                if not name.startswith("_") and name not in subid.__all__
                and not isinstance(getattr(subid, name), types.ModuleType)]
    assert "importlib" not in dir(subid)
    from subid import AdaptiveIdentifier, ls_subspace
    assert AdaptiveIdentifier is subid.methods.online.adaptive.AdaptiveIdentifier
    assert ls_subspace is sys.modules["subid.methods.dt.ls_subspace"].ls_subspace


def test_importing_an_implementation_module_keeps_the_public_function():
    import subid.methods.dt.ls_subspace  # noqa: F401  (binds subid.methods, not subid.ls_subspace)
    import subid.methods.dt.n4sid as n4sid_name
    assert isinstance(subid.ls_subspace, types.FunctionType)
    assert isinstance(n4sid_name, types.ModuleType)
    assert isinstance(subid.n4sid, types.FunctionType)
    assert isinstance(sys.modules["subid.methods.dt.ls_subspace"], types.ModuleType)


def test_unknown_name_raises_attribute_error():
    try:
        subid.no_such_name
    except AttributeError as exc:
        assert "no_such_name" in str(exc)
    else:
        raise AssertionError("expected AttributeError")


def test_import_subid_and_the_cli_load_no_heavy_module():
    out = _fresh(
        "import subid, subid.cli.commands\n"
        f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    assert out.strip() == ""


def test_fresh_interpreter_public_names_are_the_module_objects():
    out = _fresh(
        "import subid\n"
        "from subid import ct_subspace\n"
        "import subid.methods.ct.ct_subspace as m\n"
        "print(ct_subspace is m.ct_subspace is sys.modules['subid.methods.ct.ct_subspace'].ct_subspace)\n"
    )
    assert out.strip() == "True"


#: Every public module namespace of the package: ``import subid.X`` must work.
NAMESPACES = ("plot", "distributed", "basis", "interop", "registry", "systems", "datasets",
              "errors", "delay", "testing")


def test_every_public_namespace_imports_as_a_module_in_a_fresh_interpreter():
    # ``import subid.X`` and ``from subid.X import name`` (issue 29: only ``subid.X``
    # attribute access worked for plot, distributed, basis, interop and registry)
    lines = ["import subid, types"]
    for name in NAMESPACES:
        first = subid._LAZY[name][0]
        module = importlib.import_module(f"subid.{first}")
        public = module.__all__[0]
        lines += [f"import subid.{name}",
                  f"from subid.{name} import {public}",
                  f"assert isinstance(subid.{name}, types.ModuleType), {name!r}",
                  f"assert {public} is subid.{name}.{public}, {name!r}"]
    lines.append("print('ok')")
    assert _fresh("\n".join(lines)).strip() == "ok"


def test_public_namespaces_reexport_every_public_name_of_their_implementation():
    # subid.plot re-exports subid.evaluation.plot, ...: the same objects, none missing
    implementation = {"plot": "evaluation.plot", "distributed": "methods.dt.distributed",
                      "basis": "methods.ct.basis", "interop": "io.interop",
                      "registry": "methods.registry"}
    for name, where in implementation.items():
        public = importlib.import_module(f"subid.{name}")
        module = importlib.import_module(f"subid.{where}")
        assert public.__all__ == module.__all__, name
        for attribute in module.__all__:
            assert getattr(public, attribute) is getattr(module, attribute), (name, attribute)
    assert set(NAMESPACES) == {n for n, (_, attr) in subid._LAZY.items() if attr is None}


def test_importing_every_namespace_module_keeps_import_subid_lazy():
    # import subid alone loads none of the heavy modules, namespaces included in _LAZY
    out = _fresh("import subid\n"
                 "assert all(f'subid.{n}' not in sys.modules for n in "
                 "('plot', 'distributed', 'basis', 'interop', 'registry'))\n"
                 f"print(','.join(m for m in {HEAVY!r} if m in sys.modules))\n")
    assert out.strip() == ""


def test_residual_tests_and_spectral_estimate_do_not_import_scipy_stats():
    """The report's residual tests and spa take their distributions from scipy.special:
    importing scipy.stats cost a fresh `subid identify --out` 0.67 s inside the report."""
    out = _fresh(
        "import warnings; warnings.simplefilter('ignore')\n"
        "import subid\n"
        "true = subid.systems.random_system(2, 1, 1, seed=1)\n"
        "d = subid.systems.simulate_data(true, 400, seed=2, output_snr_db=20)\n"
        "m = subid.moesp(d, 2)\n"
        "subid.residuals(m, d); subid.residuals(subid.StateSpace(m.A, m.B, m.C, m.D, 1.0), d)\n"
        "subid.spa(d)\n"
        "print('scipy.stats' in sys.modules)\n"
    )
    assert out.strip() == "False"
