"""The stage registry: every stage is registered with typed params that have usable defaults; stages are found
through the entry points of installed distributions (topomatch's own and a user's), in every process."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tomllib
from importlib.metadata import EntryPoint
from pathlib import Path

import pytest

from tests_paths import REPO_ROOT
from topomatch.pipeline import registry
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.registry import REPORTS, describe_params, discover, get_input, get_report, get_stage

MINIMAL_PARAMS = {"decimate": {"ratio": 0.5}, "decimate_crosscheck": {"ratio": 0.5}}
FOUNDATION_STAGES = {"load", "clean", "decimate", "decimate_crosscheck", "noise", "transform", "measures"}


def test_foundation_stages_are_registered():
    assert FOUNDATION_STAGES <= set(discover())


@pytest.mark.parametrize("name", sorted(FOUNDATION_STAGES))
def test_stage_spec_is_complete(name):
    spec = get_stage(name)
    assert isinstance(spec.version, int) and spec.version >= 1
    assert spec.doc, f"stage {name} needs a one-line docstring"
    rows = describe_params(spec.params)
    for field, type_name, default, _ in rows:
        assert type_name, field
    # params are frozen: a stage cannot mutate its configuration
    params = spec.params.parse(MINIMAL_PARAMS.get(name, {}), name)
    with pytest.raises(Exception):
        setattr(params, next(iter(spec.params.model_fields)), None)


def test_unknown_stage_error():
    with pytest.raises(ConfigError, match="unknown stage 'nope'"):
        get_stage("nope")


def test_reports_registered():
    discover()
    assert {"table", "line_plot", "mesh_gallery"} <= set(REPORTS)


# --------------------------------------------------------------------------- entry points

PLUGIN = '''
import dataclasses

from topomatch.pipeline.contract import Params, StageResult, stage


@dataclasses.dataclass(frozen=True)
class Counted(StageResult):
    vertices: int

    def summary(self):
        return {"vertices": self.vertices}


@stage("acme_count", params=Params, version=1, consumes=("mesh",), produces=())
def count(mesh, *, params):
    """Test plug-in stage: the number of vertices."""
    return Counted(len(mesh.V))
'''


def write_distribution(folder: Path, name: str, groups: dict[str, dict[str, str]]) -> None:
    """The metadata of an installed distribution ``name`` (a ``dist-info`` folder, as pip writes it) declaring
    the entry points ``groups`` ({group: {name: "module:function"}}); ``folder`` on ``sys.path`` installs it."""
    info = folder / f"{name}-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{key} = {value}\n" for key, value in eps.items()) + "\n"
        for group, eps in groups.items()))


def pyproject_entry_points() -> dict[str, dict[str, str]]:
    """The entry-point tables of this checkout's pyproject.toml, {group: {name: "module:function"}}."""
    tables = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["project"]["entry-points"]
    return {group: tables[group] for group in registry.GROUPS.values()}


@pytest.fixture
def installed(tmp_path, monkeypatch):
    """A folder on ``sys.path`` holding this checkout's topomatch metadata (the installed one may be older) and
    whatever the test adds; the registry reads the metadata again, and its tables are restored afterwards."""
    write_distribution(tmp_path, "topomatch", pyproject_entry_points())
    monkeypatch.syspath_prepend(str(tmp_path))
    saved = {kind: dict(table) for kind, table in registry._TABLES.items()}, list(registry._SCANNED)
    registry._DECLARED.clear()
    yield tmp_path
    registry._DECLARED.clear()
    for kind, table in registry._TABLES.items():
        table.clear()
        table.update(saved[0][kind])
    registry._SCANNED[:] = saved[1]
    sys.modules.pop("acme_stages", None)


def test_entry_points_and_decorators_agree():
    """Every @stage / @report of the built-in packages is declared in pyproject.toml under its name, by the
    function that carries it, and every declared one exists: the table cannot drift from the code."""
    marked = {group: {} for group in registry.GROUPS.values()}
    for name in registry.builtin_modules():
        for spec in registry.marked(importlib.import_module(name)):
            marked[registry.GROUPS[registry.spec_kind(spec)]][spec.name] = f"{spec.func.__module__}:{spec.func.__qualname__}"
    assert pyproject_entry_points() == marked
    assert len(marked["topomatch.stages"]) >= 30 and len(marked["topomatch.reports"]) >= 20
    assert set(marked["topomatch.inputs"]) == {"meshes", "images", "pairs", "pairs_csv"}


def test_a_third_party_distribution_is_found_without_registering(installed):
    (installed / "acme_stages.py").write_text(PLUGIN)
    write_distribution(installed, "acme", {"topomatch.stages": {"acme_count": "acme_stages:count"}})
    spec = get_stage("acme_count")
    assert spec.func is sys.modules["acme_stages"].count
    assert registry.declared("stage")["acme_count"][0].dist.name == "acme"
    assert "acme_count" in discover()  # `topomatch stages` lists it too


INPUT_PLUGIN = """
from topomatch.pipeline.contract import input_kind


@input_kind("acme_list", schema=str, provides=("path",))
def mesh_list(listing, files):
    \"\"\"Test plug-in input kind: a text file naming one mesh per line.\"\"\"
    table = files.one(listing, "inputs.acme_list")
    names = [line.strip() for line in table.read_text().splitlines() if line.strip()]
    return files.each(names, "inputs.acme_list")
"""


def test_a_third_party_input_kind_is_a_key_under_inputs(installed, tmp_path):
    """A distribution declares a kind of input as it declares stages; the engine knows no kind by name."""
    from topomatch.pipeline.experiment import build_experiment
    from topomatch.pipeline.paths import BUNDLED_DIR

    (installed / "acme_inputs.py").write_text(INPUT_PLUGIN)
    write_distribution(installed, "acme", {"topomatch.inputs": {"acme_list": "acme_inputs:mesh_list"}})
    (tmp_path / "list.txt").write_text(f"{BUNDLED_DIR}/meshes/torus.off\n\n{BUNDLED_DIR}/meshes/eight_genus2.off\n")
    config = {"name": "acme", "inputs": {"acme_list": "list.txt"}, "stages": ["load", "measures"]}
    experiment = build_experiment(config, source=tmp_path / "acme.yaml")
    assert [u.primary.name for u in experiment.inputs] == ["torus.off", "eight_genus2.off"]
    assert [u.label for u in experiment.inputs] == ["{bundled}/meshes/torus.off", "{bundled}/meshes/eight_genus2.off"]
    assert get_input("acme_list").provides == ("path",)
    with pytest.raises(ConfigError, match=r"acme\.yaml: inputs\.acme_list: Input should be a valid string, got \['list.txt'\]"):
        build_experiment({**config, "inputs": {"acme_list": ["list.txt"]}}, source=tmp_path / "acme.yaml")


def test_a_name_declared_by_two_distributions_is_an_error_naming_both(installed):
    (installed / "acme_stages.py").write_text(PLUGIN)
    write_distribution(installed, "acme", {"topomatch.stages": {"decimate": "acme_stages:count"}})
    registry.STAGES.pop("decimate", None)
    with pytest.raises(ConfigError, match=r"stage 'decimate' is declared twice: by acme_stages:count \(distribution "
                                          r"acme\) and by topomatch.stages.mesh.decimate:decimate \(distribution "
                                          r"topomatch\)"):
        get_stage("decimate")


def test_a_stage_defined_twice_is_an_error_naming_both_modules(installed):
    """With metadata that does not declare the built-in name (an install older than the code), importing
    everything still finds the clash."""
    (installed / "acme_stages.py").write_text(PLUGIN.replace('"acme_count"', '"decimate"'))
    write_distribution(installed, "acme", {"topomatch.stages": {"decimate": "acme_stages:count"}})
    entries = registry.declared("stage")
    entries["decimate"] = [ep for ep in entries["decimate"] if ep.dist.name == "acme"]
    registry._SCANNED.clear()
    with pytest.raises(ConfigError, match="stage 'decimate' is defined twice: in topomatch.stages.mesh.decimate and "
                                          "acme_stages"):
        discover()


def test_a_broken_third_party_entry_point_names_its_distribution(installed):
    write_distribution(installed, "acme", {"topomatch.reports": {"acme_report": "acme_missing:report"}})
    with pytest.raises(ConfigError, match=r"report 'acme_report': cannot load the entry point acme_missing:report "
                                          r"\(distribution acme\): ModuleNotFoundError"):
        get_report("acme_report")


def test_an_out_of_date_builtin_entry_falls_back_to_importing_the_builtins(installed):
    """An editable install's metadata names a module that the code no longer has: the name is still found."""
    entries = registry.declared("stage")
    entries["noise"] = [EntryPoint("noise", "topomatch.stages.mesh.moved_away:noise", "topomatch.stages")]
    registry.STAGES.pop("noise", None)
    registry._SCANNED.clear()
    assert get_stage("noise").func.__module__ == "topomatch.stages.mesh.noise"


def _fresh_python(code: str, path: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(path), str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=path,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_a_command_imports_only_the_stages_it_runs(installed):
    """Looking up the registration stages (as ``topomatch register`` does) imports no mesh, spectral, Reeb or
    retrieval module: the metadata names the one module of each stage."""
    code = ("import sys; from topomatch.pipeline.registry import get_stage, get_report\n"
            "for name in ('load_pair', 'misalign', 'register', 'evaluate'): get_stage(name)\n"
            "get_report('registration_table')\n"
            "print(' '.join(sorted(m for m in sys.modules if m.startswith('topomatch.stages.'))))")
    loaded = _fresh_python(code, installed).split()
    assert "topomatch.stages.registration.register" in loaded
    assert not [m for m in loaded if m.split(".")[2] in ("mesh", "spectral", "morse", "reeb", "retrieval", "matching")]


def test_a_third_party_stage_reaches_the_worker_processes(installed, tmp_path):
    """The pool's worker processes find the plug-in by its metadata (nobody calls register_module there) and
    store its results in the cache: a second run is all cache hits."""
    (installed / "acme_stages.py").write_text(PLUGIN)
    write_distribution(installed, "acme", {"topomatch.stages": {"acme_count": "acme_stages:count"}})
    (tmp_path / "acme.yaml").write_text(
        "name: acme\ninputs: {meshes: ['{bundled}/meshes/torus.off', '{bundled}/meshes/eight_genus2.off']}\n"
        "stages: [load, acme_count]\nexecutor: {workers: 2}\n")
    code = ("import json, sys; from topomatch.cli import main\n"
            "for _ in range(2): main(['run', 'acme.yaml', '--out', 'runs', '-q'])\n"
            "manifest = json.load(open(next(__import__('pathlib').Path('runs').glob('acme-*/manifest.json'))))\n"
            "print(json.dumps([item['cache_hits'] for item in manifest['items']]))")
    hits = json.loads(_fresh_python(code, installed).splitlines()[-1])
    assert hits == [{"load": True, "acme_count": True}] * 2
