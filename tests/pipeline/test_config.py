"""Config loading and validation: every config in configs/ validates; errors name the key path."""

from __future__ import annotations

from pathlib import Path

import pytest

from topomatch.pipeline.config import apply_overrides, build_experiment, load_experiment
from topomatch.pipeline.errors import ConfigError, InputError
from topomatch.pipeline.paths import data_root

REPO = Path(__file__).resolve().parents[2]
CONFIGS = sorted((REPO / "configs").rglob("*.yaml"))


def test_there_are_configs():
    assert any(p.name == "demo.yaml" for p in CONFIGS)


@pytest.mark.parametrize("path", CONFIGS, ids=[str(p.relative_to(REPO / "configs")) for p in CONFIGS])
def test_every_config_validates(path):
    root = data_root()
    needs_root = "{data_root}" in path.read_text()
    if needs_root and root is None:
        pytest.skip("config needs the external data root (TOPOMATCH_DATA_ROOT)")
    experiment = load_experiment(path, data_root=root)
    assert experiment.items(), "a config must produce at least one item"


def test_unknown_top_level_key_is_named(small_config):
    small_config["stagse"] = []
    with pytest.raises(ConfigError, match=r"stagse: unknown key"):
        build_experiment(small_config)


def test_unknown_stage_param_is_named_with_its_path(small_config):
    small_config["stages"][2] = {"noise": {"sigmaa": 0.1}}
    with pytest.raises(ConfigError, match=r"stages\[2\]\.noise\.sigmaa: unknown key"):
        build_experiment(small_config)


def test_wrong_type_is_rejected_without_coercion(small_config):
    small_config["stages"][2] = {"noise": {"sigma": "0.1"}}
    with pytest.raises(ConfigError, match=r"stages\[2\]\.noise\.sigma: .*got '0\.1'"):
        build_experiment(small_config)


def test_unknown_stage_lists_known_ones(small_config):
    small_config["stages"].append("reeb_grap")
    with pytest.raises(ConfigError, match=r"stages\[4\]: unknown stage 'reeb_grap'; known stages: .*load"):
        build_experiment(small_config)


def test_stage_without_its_input_is_rejected(small_config):
    small_config["stages"] = ["measures"]
    with pytest.raises(ConfigError, match=r"stages\[0\]\.measures: needs 'mesh'"):
        build_experiment(small_config)


def test_bad_sweep_value_is_named(small_config):
    small_config["sweep"] = {"noise.sigma": [0.0, "big"]}
    with pytest.raises(ConfigError, match=r"sweep\.noise\.sigma\[1\]"):
        build_experiment(small_config)


def test_sweep_of_unknown_param(small_config):
    small_config["sweep"] = {"noise.sigm": [0.0]}
    with pytest.raises(ConfigError, match=r"no parameter 'sigm'"):
        build_experiment(small_config)


def test_sweep_expands_to_the_product(small_config):
    small_config["sweep"] = {"noise.sigma": [0.0, 0.01, 0.02], "noise.seed": [1, 2]}
    experiment = build_experiment(small_config)
    items = experiment.items()
    assert len(items) == 2 * 3 * 2
    sigmas = {item.calls[2].params.sigma for item in items}
    assert sigmas == {0.0, 0.01, 0.02}


def test_sweep_one_at_a_time(small_config):
    small_config["sweep"] = {"noise.sigma": [0.0, 0.01, 0.02], "noise.seed": [1, 2]}
    small_config["sweep_mode"] = "one_at_a_time"
    points = build_experiment(small_config).sweep_points()
    assert points == [{"noise.sigma": 0.0, "noise.seed": 1}, {"noise.sigma": 0.01, "noise.seed": 1},
                      {"noise.sigma": 0.02, "noise.seed": 1}, {"noise.sigma": 0.0, "noise.seed": 2}]
    small_config["sweep_mode"] = "diagonal"
    with pytest.raises(ConfigError, match="sweep_mode"):
        build_experiment(small_config)


def test_yaml_anchor_free_safe_loading(tmp_path):
    bad = tmp_path / "evil.yaml"
    bad.write_text("name: !!python/object/apply:os.system ['echo hi']\nstages: [load]\n")
    with pytest.raises(ConfigError, match="evil.yaml: not valid YAML"):
        load_experiment(bad)


def test_missing_config_file_names_it(tmp_path):
    with pytest.raises(InputError, match="nope.yaml: config file not found"):
        load_experiment(tmp_path / "nope.yaml")


def test_missing_input_file_names_it(small_config, write_config):
    small_config["inputs"]["meshes"].append("/no/such/mesh.off")
    with pytest.raises(InputError, match="/no/such/mesh.off: file not found"):
        load_experiment(write_config(small_config))


def test_data_root_required_when_used(small_config, write_config, monkeypatch):
    monkeypatch.delenv("TOPOMATCH_DATA_ROOT", raising=False)
    small_config["inputs"]["meshes"] = ["{data_root}/meshes/classic/torus.off"]
    with pytest.raises(ConfigError, match="needs the external data root"):
        load_experiment(write_config(small_config), data_root=data_root())


def test_overrides_set_stage_params_and_keys(small_config):
    data = apply_overrides(small_config, ["noise.seed=5", "executor.kind=dask", "name=other"])
    experiment = build_experiment(data)
    assert experiment.calls[2].params.seed == 5
    assert experiment.raw.executor.kind == "dask"
    assert experiment.name == "other"
    assert small_config["name"] == "small", "overrides must not mutate the input"


def test_override_of_a_swept_parameter_is_refused(small_config):
    # the sweep sets noise.sigma at every point: a chain value would change the run's config and nothing else
    swept = small_config  # it sweeps noise.sigma over [0.0, 0.01]
    with pytest.raises(ConfigError, match=r"sweeps noise.sigma over \[0.0, 0.01\].*--set 'sweep.noise.sigma=\[0.02\]'"):
        apply_overrides(swept, ["noise.sigma=0.02"])
    data = apply_overrides(swept, ["sweep.noise.sigma=[0.02]"])
    assert [p["noise.sigma"] for p in build_experiment(data).sweep_points()] == [0.02]


def test_override_of_absent_stage(small_config):
    with pytest.raises(ConfigError, match="0 stages called 'decimate'"):
        apply_overrides(small_config, ["decimate.ratio=0.5"])


def test_content_hash_tracks_params_not_executor(small_config):
    a = build_experiment(small_config)
    b = build_experiment(apply_overrides(small_config, ["executor.kind=dask"]))
    c = build_experiment(apply_overrides(small_config, ["noise.seed=4"]))
    assert a.content_hash() == b.content_hash()
    assert a.content_hash() != c.content_hash()


def test_a_chain_that_reads_files_needs_inputs(small_config):
    # an empty input list was reported as the first stage needing 'path' "which neither the inputs nor an earlier
    # stage provide"; it is the inputs that are missing
    small_config["inputs"] = {"meshes": []}
    with pytest.raises(ConfigError, match=r"inputs: the chain reads input files, and the config lists none"):
        build_experiment(small_config)


@pytest.mark.parametrize("inputs, message", [
    ({"mesh": ["a.off"]}, r"^inputs\.mesh: unknown kind of input 'mesh'; known kinds of input: images, meshes, pairs, "
                          r"pairs_csv$"),
    ({"meshes": "a.off"}, r"^inputs\.meshes: Input should be a valid array, got 'a.off'$"),
    ({"pairs": [{"fixed": "a.png"}]}, r"^inputs\.pairs\[0\]\.moving: Field required$"),
    ({"pairs_csv": {"path": "p.csv", "fixed_col": "f"}}, r"^inputs\.pairs_csv\.fixed_col: unknown key"),
])
def test_inputs_are_checked_by_the_kind_that_each_key_names(small_config, inputs, message):
    small_config["inputs"] = inputs
    with pytest.raises(ConfigError, match=message):
        build_experiment(small_config)


@pytest.mark.parametrize("executor, message", [
    ({"kind": "local", "address": "tcp://h:8786"}, r"^executor\.address \(--address\) applies only to the dask executor"),
    ({"address": "tcp://h:8786"}, r"^executor\.address .*the executor is local"),
    ({"kind": "local", "timeout": 5}, r"^executor\.timeout \(--dask-timeout\) applies only to the dask executor"),
    ({"kind": "dask", "address": "tcp://h:8786", "workers": 2},
     r"^executor\.workers \(2, --workers\) does not apply with the dask scheduler at tcp://h:8786 \(from "
     r"executor\.address\): that cluster decides its workers"),
])
def test_executor_settings_that_do_not_apply_are_refused(small_config, executor, message, monkeypatch):
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)
    small_config["executor"] = executor
    with pytest.raises(ConfigError, match=message):
        build_experiment(small_config)


def test_the_scheduler_address_comes_from_the_config_then_the_environment(small_config, monkeypatch):
    from topomatch.pipeline.config import ExecutorConfig

    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://env:8786")
    assert ExecutorConfig(kind="dask", address="tcp://given:1").scheduler() == ("tcp://given:1", "executor.address")
    assert ExecutorConfig(kind="dask").scheduler() == ("tcp://env:8786", "$DASK_SCHEDULER_ADDRESS")
    assert ExecutorConfig(kind="local").scheduler() == (None, "")  # the local executor ignores the environment
    build_experiment({**small_config, "executor": {"kind": "local", "workers": 2}})
    # the environment's address is the cluster's: a local cluster size does not apply, and the message says where
    # the address came from
    small_config["executor"] = {"kind": "dask", "workers": 2}
    with pytest.raises(ConfigError, match=r"from \$DASK_SCHEDULER_ADDRESS\).*unset \$DASK_SCHEDULER_ADDRESS to start "
                                          r"a local cluster of 2 workers"):
        build_experiment(small_config)
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS")
    assert ExecutorConfig(kind="dask").scheduler() == (None, "")
    assert build_experiment(small_config).raw.executor.workers == 2


def test_numpy_scalars_are_their_python_numbers_and_other_objects_are_refused():
    """An option computed with numpy (``seed=np.int64(3)`` in any API call) validates as its Python number; an
    object JSON cannot hold is still refused as not a plain YAML value."""
    import numpy as np

    from topomatch.stages.registration.params import RegisterParams

    parsed = RegisterParams.parse({"seed": np.int64(3), "metric": {"alpha": np.float32(1.5)}}, "register")
    assert parsed.seed == 3 and parsed.metric.alpha == 1.5
    with pytest.raises(ConfigError, match="plain YAML scalars"):
        RegisterParams.parse({"seed": object()}, "register")
