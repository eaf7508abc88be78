"""The layout's rules, checked on the source (imports inside functions included):

- the engine (``topomatch.pipeline``) imports no domain module (``topomatch.stages``) and nothing of
  the application layer (the rest of ``topomatch``);
- the stages import only the contract (``topomatch.pipeline.contract``) from the engine, and nothing of
  the application layer;
- no import circles between modules;
- at most 3 imports run "upwards" between the domains, in the order below;
- no ``pickle`` anywhere in the engine or the stages;
- every package folder is listed in pyproject.toml, and the bundled data and configs are package data.
"""

from __future__ import annotations

import ast
import fnmatch
import tomllib
from pathlib import Path

import pytest

from tests_paths import REPO_ROOT

#: Import name -> source folder (pyproject.toml's package-dir).
ROOTS = {"topomatch": REPO_ROOT / "topomatch", "topomatch.pipeline": REPO_ROOT / "pipeline",
         "topomatch.stages": REPO_ROOT / "stages"}

#: The domains, lower first: a domain may import the ones before it.
DOMAIN_ORDER = ("optimize", "imaging", "mesh", "adapters", "spectral", "morse", "reeb", "matching", "retrieval", "registration",
                "crosscheck")


def _modules() -> dict[str, Path]:
    mods = {}
    for prefix, folder in ROOTS.items():
        for f in folder.rglob("*.py"):
            parts = list(f.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join([prefix, *parts])] = f
    return mods


def _imports(mods: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the project modules it imports (anywhere in the file)."""
    graph = {}
    for name, path in mods.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    pkg = name.split(".")[: len(name.split(".")) - node.level + (path.name == "__init__.py")]
                    base = ".".join(pkg + ([node.module] if node.module else []))
                found.add(base)
                found.update(f"{base}.{a.name}" for a in node.names)
        targets = set()
        for target in found:
            while target and target not in mods:
                target = target.rpartition(".")[0]
            if target and target not in (name, "topomatch"):
                targets.add(target)
        graph[name] = targets
    return graph


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return _imports(_modules())


def _is_app(name: str) -> bool:
    return not name.startswith(("topomatch.pipeline", "topomatch.stages"))


def test_engine_imports_no_domain_and_no_app(graph):
    bad = {m: sorted(t for t in ts if not t.startswith("topomatch.pipeline"))
           for m, ts in graph.items() if m.startswith("topomatch.pipeline")}
    assert not {m: t for m, t in bad.items() if t}


def test_stages_import_only_the_contract(graph):
    bad = {}
    for m, ts in graph.items():
        if m.startswith("topomatch.stages"):
            wrong = [t for t in ts if (t.startswith("topomatch.pipeline") and t != "topomatch.pipeline.contract")
                     or _is_app(t)]
            if wrong:
                bad[m] = wrong
    assert not bad


def test_no_import_circles(graph):
    index, low, stack, on_stack, circles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
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
                circles.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    assert not circles


def test_few_upward_imports_between_domains(graph):
    upward = []
    for m, ts in graph.items():
        if not m.startswith("topomatch.stages."):
            continue
        a = m.split(".")[2]
        for t in ts:
            if t.startswith("topomatch.stages."):
                b = t.split(".")[2]
                assert a in DOMAIN_ORDER and b in DOMAIN_ORDER, f"add the domain of {m} / {t} to DOMAIN_ORDER"
                if DOMAIN_ORDER.index(b) > DOMAIN_ORDER.index(a):
                    upward.append(f"{m} -> {t}")
    assert len(upward) <= 3, upward


def test_no_pickle_in_the_engine_or_the_stages():
    for folder in (ROOTS["topomatch.pipeline"], ROOTS["topomatch.stages"]):
        for f in folder.rglob("*.py"):
            for node in ast.walk(ast.parse(f.read_text())):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
                assert not any(n.split(".")[0] in ("pickle", "cPickle", "dill", "cloudpickle") for n in names), f


def test_every_package_folder_is_packaged():
    config = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    dirs = {prefix: REPO_ROOT / d for prefix, d in config["package-dir"].items()}
    expected = set()
    for prefix, folder in dirs.items():
        for d in [folder, *[p for p in folder.rglob("*") if p.is_dir()]]:
            if "__pycache__" in d.parts:
                continue
            expected.add(".".join([prefix, *d.relative_to(folder).parts]))
    assert expected == listed
    data = config["package-data"]
    for prefix in ("topomatch.data", "topomatch.configs"):
        folder = dirs[prefix]
        for f in folder.rglob("*"):
            if f.is_file():
                package = ".".join([prefix, *f.parent.relative_to(folder).parts])
                assert any(fnmatch.fnmatch(f.name, p) for p in data.get(package, [])), f"{f} is not package data"
