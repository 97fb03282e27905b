"""Package layering: no import circle, and no package reaching up to a layer above it at import time.

Layers, bottom up: ``rvpaper`` (data) and ``rsm`` (statistics) -> ``rvcad`` (geometry) -> ``rvdyn``
(solver, runner) and ``rvrig`` (measured records) -> ``rvcalib`` (loop on measured data) and ``rvstudy`` (the
study); a command line
may sit above its package's library (``rvcad export --pose solved`` uses rvdyn). ``rvdyn`` does not
import matplotlib at module level (plots import it inside the function that draws).
"""
from __future__ import annotations

import ast
import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rvpaper", "rsm", "rvcad", "rvdyn", "rvrig", "rvcalib", "rvstudy")

#: package -> top-level packages it must not load at import time (its own modules, all of them imported).
FORBIDDEN = {
    "rvpaper": {"rsm", "rvcad", "rvdyn", "rvrig", "rvcalib", "rvstudy", "matplotlib"},
    "rsm": {"rvpaper", "rvcad", "rvdyn", "rvrig", "rvcalib", "rvstudy"},
    "rvcad": {"rvrig", "rvcalib", "rvstudy", "matplotlib"},
    "rvdyn": {"rvrig", "rvcalib", "rvstudy", "matplotlib"},
    "rvrig": {"rvdyn", "rvcalib", "rvstudy", "matplotlib"},
    "rvcalib": {"rvstudy"},
}
#: Also forbidden, but to the package's library modules only: its command line (``cli``, ``__main__``)
#: is an application on top (``rvcad export --pose solved`` places the parts at rvdyn's equilibrium).
FORBIDDEN_IN_LIBRARY = {"rvcad": {"rvdyn"}}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _import_time_imports(path: Path, lazy: bool = False) -> set[str]:
    """Names imported by a module's top-level statements (not inside functions or methods, not under
    ``if TYPE_CHECKING``), resolved to absolute module names; ``lazy=True``: also inside functions."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    me = _module_name(path)
    pkg = me if path.name == "__init__.py" else me.rpartition(".")[0]
    found: set[str] = set()

    def visit(nodes: list[ast.stmt]) -> None:
        for n in nodes:
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and not lazy:
                continue  # runs when called, not at import
            if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test):
                visit(n.orelse)
                continue
            if isinstance(n, ast.Import):
                found.update(a.name for a in n.names)
            elif isinstance(n, ast.ImportFrom):
                base = n.module or ""
                if n.level:
                    parts = pkg.split(".")
                    base = ".".join(parts[: len(parts) - (n.level - 1)] + ([n.module] if n.module else []))
                found.add(base)
                found.update(f"{base}.{a.name}" for a in n.names)
            for field in ("body", "orelse", "finalbody", "handlers"):  # if/try/with/for/while/class bodies
                sub = getattr(n, field, None)
                if isinstance(sub, list):
                    visit([x for x in sub if isinstance(x, ast.stmt)])
                    for h in sub:
                        if isinstance(h, ast.ExceptHandler):
                            visit(h.body)

    visit(tree.body)
    return found


@functools.lru_cache(maxsize=2)
def _imports(lazy: bool = False) -> dict[str, set[str]]:
    """Every project module -> the names it imports (project and third party); at import time only,
    or with ``lazy`` also those imported inside functions."""
    return {_module_name(p): _import_time_imports(p, lazy) for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}


def _ancestors(name: str) -> set[str]:
    """The packages above a dotted module name: ``a.b.c`` -> ``{"a", "a.b"}``."""
    return {".".join(name.split(".")[:i]) for i in range(1, name.count(".") + 1)}


def _graph_of(files: dict[str, set[str]]) -> dict[str, set[str]]:
    """Project module -> project modules it loads, from module -> imported names (:func:`_imports`).

    A name the module imports counts as written, ``__init__`` modules included: ``from rvdyn import
    collision`` in ``rvdyn.fcl_contacts`` loads ``rvdyn`` (its ``__init__``) and ``rvdyn.collision``. The
    packages above an imported module load first, so they count too (``import rsm.model`` loads ``rsm``),
    except the module's own packages: they are already loading when it runs, and importing a sibling
    (``from rvdyn.collision import x``) does not go through them."""
    graph = {}
    for name, imported in files.items():
        deps = {d for d in imported if d in files and d != name}
        implicit = {a for d in deps for a in _ancestors(d)} - _ancestors(name)
        graph[name] = (deps | implicit) - {name}
    return graph


@functools.lru_cache(maxsize=2)
def _graph(lazy: bool = False) -> dict[str, set[str]]:
    """Project module -> project modules it loads; see :func:`_graph_of` and :func:`_imports`."""
    return _graph_of(_imports(lazy))


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(1000, sys.getrecursionlimit()))
    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_cycle_finder_finds_a_circle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_graph_counts_a_package_init_imported_by_name():
    """``from p import b`` in ``p.a`` goes through ``p/__init__``, which imports ``p.a``: a circle; ``from p.b
    import x`` does not."""
    init_circle = {"p": {"p.a"}, "p.a": {"p", "p.b"}, "p.b": set()}
    assert _cycles(_graph_of(init_circle)) == [["p", "p.a"]]
    assert _cycles(_graph_of({"p": {"p.a"}, "p.a": {"p.b", "p.b.x"}, "p.b": set()})) == []
    assert _graph_of({"q.m": {"p.b"}, "p": set(), "p.b": set()})["q.m"] == {"p", "p.b"}  # another package's init


def test_graph_sees_import_time_imports_only():
    g = _graph()
    assert "rvdyn.te" in g["rvdyn.runner"] and "rvdyn.cache" in g["rvdyn.runner"]
    assert "rvdyn.fcl_contacts" not in g["rvdyn.te"]  # imported inside make_contacts, when asked for


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_circle(package):
    """No two modules import each other, directly or through others, even inside functions."""
    circles = [c for c in _cycles(_graph(lazy=True)) if any(m == package or m.startswith(package + ".") for m in c)]
    assert circles == [], f"import circles through {package}: {circles}"


@pytest.mark.parametrize("package", PACKAGES)
def test_no_module_imports_its_own_package_init(package):
    """A module imports its siblings directly (``from rvdyn.collision import x``, ``import rvdyn.collision as
    collision``), never through its own package's ``__init__`` (``from rvdyn import collision``), even inside a
    function: the ``__init__`` imports the package's modules, so that closes a circle."""
    files = _imports(lazy=True)
    bad = {m: sorted(names & _ancestors(m)) for m, names in files.items()
           if (m == package or m.startswith(package + ".")) and names & _ancestors(m)}
    assert bad == {}, f"modules importing their own package's __init__: {bad}"


def _loaded_at_import(module: str, lazy: bool = False) -> set[str]:
    """Top-level packages (project and third party) a module loads at import time (``lazy``: at any
    time), following the project modules it imports (static: the import statements)."""
    graph, imports = _graph(lazy), _imports(lazy)
    seen, todo = set(), [module]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        todo.extend(graph[m])
    return {name.split(".")[0] for m in seen for name in imports[m] if name}


def test_loaded_at_import_follows_project_imports():
    assert {"rvcad", "numpy", "pandas"} <= _loaded_at_import("rvdyn.te")
    assert "fcl" in _loaded_at_import("rvdyn.fcl_contacts") and "fcl" not in _loaded_at_import("rvdyn.te")
    assert "fcl" in _loaded_at_import("rvdyn.te", lazy=True)  # make_contacts imports the fcl provider
    assert "matplotlib" in _loaded_at_import("rvdyn.api", lazy=True)  # Result.plot, when called


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_does_not_import_a_higher_layer(package):
    """Project packages above it: never, not even inside a function; matplotlib: not at import time."""
    mine = [m for m in _graph() if m == package or m.startswith(package + ".")]
    library = {m for m in mine if m.rpartition(".")[2] not in ("cli", "__main__")}
    bad = {m: sorted((_loaded_at_import(m, lazy=True) & FORBIDDEN[package] - {"matplotlib"})
                     | (_loaded_at_import(m) & FORBIDDEN[package] & {"matplotlib"})
                     | (_loaded_at_import(m, lazy=True) & FORBIDDEN_IN_LIBRARY.get(package, set()) if m in library
                        else set())) for m in mine}
    assert {m: b for m, b in bad.items() if b} == {}


@pytest.mark.slow
def test_rvdyn_loads_no_study_no_loop_no_matplotlib_at_import():
    """The same at run time: every rvdyn module imported in a fresh interpreter (this also sees what the
    third-party libraries load)."""
    code = (
        "import importlib, json, pkgutil, sys\n"
        "import rvdyn\n"
        "for m in pkgutil.walk_packages(rvdyn.__path__, 'rvdyn.'):\n"
        "    if not m.name.endswith('__main__'):\n"
        "        importlib.import_module(m.name)\n"
        "print(json.dumps(sorted({k.split('.')[0] for k in sys.modules})))\n")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    loaded = set(json.loads(done.stdout.splitlines()[-1]))
    assert {"rvdyn", "rvcad", "fcl"} <= loaded  # every module was imported (fcl by rvdyn.collision)
    assert loaded & FORBIDDEN["rvdyn"] == set()


#: Test files still importing private names (none left; keep the set for work in progress).
PRIVATE_IMPORTS_PENDING: set[str] = set()


def _private_uses(path: Path) -> list[str]:
    """``module._name`` names a test file takes from the project's packages (imports and attributes)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    aliases: dict[str, str] = {}
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.module and n.module.split(".")[0] in PACKAGES:
            for a in n.names:
                if a.name.startswith("_") and not a.name.startswith("__"):
                    out.append(f"{n.module}.{a.name}")
                else:
                    aliases[a.asname or a.name] = f"{n.module}.{a.name}"
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.name.split(".")[0] in PACKAGES:
                    aliases[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
    for n in ast.walk(tree):
        if (isinstance(n, ast.Attribute) and n.attr.startswith("_") and not n.attr.startswith("__")
                and isinstance(n.value, (ast.Name, ast.Attribute))):
            base = ast.unparse(n.value)
            head = base.split(".")[0]
            if head in aliases:
                out.append(f"{aliases[head]}{base[len(head):]}.{n.attr}")
        # by name: setattr/getattr/monkeypatch.setattr(module, "_name", ...) and monkeypatch.setattr("pkg.mod._name", ...)
        if (isinstance(n, ast.Call) and n.args and (ast.unparse(n.func).split(".")[-1] in ("setattr", "getattr",
                                                                                         "delattr", "hasattr"))):
            a0 = n.args[0]
            if (len(n.args) > 1 and isinstance(n.args[1], ast.Constant) and isinstance(n.args[1].value, str)
                    and isinstance(a0, (ast.Name, ast.Attribute))):
                base = ast.unparse(a0)
                head = base.split(".")[0]
                name = n.args[1].value
                if head in aliases and name.startswith("_") and not name.startswith("__"):
                    out.append(f"{aliases[head]}{base[len(head):]}.{name}")
            elif isinstance(a0, ast.Constant) and isinstance(a0.value, str) and "." in a0.value:
                parts = a0.value.split(".")
                if parts[0] in PACKAGES and any(q.startswith("_") and not q.startswith("__") for q in parts[1:]):
                    out.append(a0.value)
    return sorted(set(out))


def test_private_use_finder(tmp_path):
    probe = tmp_path / "test_probe.py"
    probe.write_text("import rvdyn.runner as r\n"
                     "from rvcad.export import _atomic_write, export_case\n"
                     "from rvcad import parts\n"
                     "r._hidden(); parts._Gear; export_case.__doc__; other._x\n"
                     "monkeypatch.setattr(r, '_RUNNER', None); getattr(parts, 'public'); setattr(other, '_y', 1)\n"
                     "monkeypatch.setattr('rvcalib.reducer_model._solve', None); monkeypatch.setattr('os.path._x', 1)\n")
    assert _private_uses(probe) == ["rvcad.export._atomic_write", "rvcad.parts._Gear", "rvcalib.reducer_model._solve",
                                    "rvdyn.runner._RUNNER", "rvdyn.runner._hidden"]


def test_tests_use_public_names_only():
    """Every Python file of the tests (test modules, conftest.py and their helper modules)."""
    bad = {p.name: _private_uses(p) for p in sorted((ROOT / "tests").glob("*.py"))
           if p.name not in PRIVATE_IMPORTS_PENDING}
    assert {k: v for k, v in bad.items() if v} == {}
