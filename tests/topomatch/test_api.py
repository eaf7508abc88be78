"""The public Python API as a user calls it: same results, fields and defaults as the command line."""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import subprocess
import sys

import numpy as np
import pytest

import topomatch
from topomatch.cli import build_parser, main
from topomatch.pipeline.cli_options import field_of
from tests_paths import BUNDLED_MESHES, ITK_DIR


def cli_json(capsys, *args):
    code = main([*map(str, args), "--json"])
    out, _ = capsys.readouterr()
    assert code == 0
    return json.loads(out)


def test_import_is_lazy_and_lists_the_api():
    code = ("import sys, topomatch; print('topomatch.pipeline.config' in sys.modules, "
            "'numpy' in sys.modules, callable(topomatch.skeleton))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "False", "True"]
    assert {"read_mesh", "skeleton", "match", "index", "open_index", "register", "run_config"} <= set(topomatch.__all__)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        topomatch.nope  # noqa: B018


def test_skeleton_of_a_mesh_equals_the_command(capsys):
    path = BUNDLED_MESHES / "eight_genus2.off"
    mesh = topomatch.read_mesh(path)
    assert mesh.n_vertices > 0 and mesh.F.dtype == np.int64
    api = topomatch.skeleton(mesh)
    cli = cli_json(capsys, "skeleton", path)
    assert set(cli) == set(topomatch.Skeleton.JSON_FIELDS)
    for key in cli:
        if key not in ("mesh", "seconds"):
            assert api.to_dict()[key] == pytest.approx(cli[key]), key
    assert api.genus == 2 and api.cycle_rank == 2 and api.function == "fiedler"
    assert api.n_endpoints == len(api.endpoints) and api.graph.number_of_nodes() == api.n_nodes
    assert api.values.shape == (api.n_vertices,)


def test_skeleton_options_and_errors(tmp_path):
    s = topomatch.skeleton(BUNDLED_MESHES / "torus.off", function="mixture", levels=30)
    assert s.function == "mixture" and s.levels == 30 and s.cycle_rank == 1 and s.lambda2 is None
    with pytest.raises(topomatch.ConfigError, match="levels"):
        topomatch.skeleton(BUNDLED_MESHES / "torus.off", levels=1)
    with pytest.raises(topomatch.InputError, match="none.off: file not found"):
        topomatch.skeleton(tmp_path / "none.off")
    files = topomatch.write_skeleton_files(s, tmp_path / "out", ["ply", "graphml"])
    assert all((tmp_path / "out" / name).is_file() for name in ("skeleton.ply", "skeleton.graphml", "skeleton.png"))
    assert len(files) == 5
    with pytest.raises(topomatch.ConfigError, match="formats must be among ply, obj, graphml, json, got stl"):
        topomatch.write_skeleton_files(s, tmp_path / "out", ["stl"])


def test_a_non_manifold_mesh_is_skeletonised_with_a_warning(capsys):
    V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    # two octahedra sharing one vertex: a non-manifold vertex, nothing to repair
    pinched = topomatch.Mesh(np.vstack([V, V + [2, 0, 0]]), np.vstack([F, np.where(F == 1, 0, F + 6)]), name="pinched")
    s = topomatch.skeleton(pinched)
    assert len(s.warnings) == 1 and "1 non-manifold vertices" in s.warnings[0]
    assert topomatch.skeleton(BUNDLED_MESHES / "torus.off").warnings == []


def test_match_equals_the_command(capsys):
    a, b = BUNDLED_MESHES / "odedstein_human_man.obj.gz", BUNDLED_MESHES / "odedstein_human_woman.obj.gz"
    api = topomatch.match(a, b, method="srg")
    cli = cli_json(capsys, "match", a, b, "--method", "srg")
    assert api.to_dict() == cli
    assert topomatch.match(a, a, method="d2").dissimilarity == 0.0


def test_index_open_query_evaluate(tmp_path):
    names = ["torus.off", "eight_genus2.off", "odedstein_cat-low-resolution.obj.gz", "odedstein_spot_low_resolution.obj.gz"]
    paths = [BUNDLED_MESHES / n for n in names]
    report = topomatch.index(paths, tmp_path / "s.db", method="d2", workers=1)
    assert [p.done for p in report.parts] == [4] and report.n_files == 4
    collection = topomatch.open_index(tmp_path / "s.db")
    q = collection.query(paths[2], k=2, method="d2")
    assert q.indexed == 4 and q.results[0]["path"] == str(paths[2].resolve()) and q.results[0]["dissimilarity"] == 0
    with pytest.raises(topomatch.ConfigError, match="no shapes indexed for method 'hks'"):
        collection.query(paths[2], method="hks")


def test_register_images_in_memory_equals_the_command(capsys):
    fixed_path, moving_path = ITK_DIR / "BrainProtonDensitySliceBorder20.png", ITK_DIR / "BrainProtonDensitySliceShifted13x17y.png"
    fixed, moving = topomatch.read_image(fixed_path), topomatch.read_image(moving_path)
    api = topomatch.register(fixed, moving)
    cli = cli_json(capsys, "register", fixed_path, moving_path)
    assert set(cli) == set(api.to_dict())
    for key in ("tx", "ty", "angle", "parameters", "matrix", "objective", "iterations", "ok", "metric", "alpha",
                "method", "flags"):
        assert api.to_dict()[key] == cli[key], key
    assert api.ok and api.tx == pytest.approx(13, abs=0.1) and api.ty == pytest.approx(17, abs=0.1)


def test_register_params_are_the_commands_set(capsys):
    """``params`` reaches every parameter as ``--set`` does: the same result, the threshold recorded where the reason
    quotes it; and MI reports its order, 1."""
    fixed_path, moving_path = ITK_DIR / "BrainT1Slice.png", ITK_DIR / "BrainProtonDensitySliceR10X13Y17.png"
    api = topomatch.register(fixed_path, moving_path, metric="mi", params={"check": {"min_prominence": 1e6}})
    code = main(["register", str(fixed_path), str(moving_path), "--metric", "mi", "--set", "check.min_prominence=1e6",
                 "--json"])
    cli = json.loads(capsys.readouterr().out)
    assert code == 1  # flagged by the threshold set either way
    assert api.to_dict()["parameters"] == cli["parameters"] and not api.ok and "prominence" in api.to_dict()["flags"]
    assert api.to_dict()["alpha"] == cli["alpha"] == 1.0
    with pytest.raises(topomatch.ConfigError, match=r"^params\.check\.bogus: unknown key"):
        topomatch.register(fixed_path, moving_path, params={"check": {"bogus": 1}})
    with pytest.raises(topomatch.ConfigError, match=r"^params\.check\.min_flatness: .*got -1"):  # named as written
        topomatch.register(fixed_path, moving_path, params={"check": {"min_flatness": -1}})


def test_run_config_finds_installed_configs(tmp_path, monkeypatch):
    from topomatch.experiments import find_config

    monkeypatch.chdir(tmp_path)  # not the repository: configs/ here does not exist
    assert find_config("configs/registration/demo.yaml").is_file()
    assert find_config("registration/demo") == find_config("configs/registration/demo.yaml")
    outcome = topomatch.run_config("configs/registration/demo.yaml", out=tmp_path / "runs")
    assert not outcome.failed and (outcome.run_dir / "index.html").is_file()
    with pytest.raises(topomatch.InputError, match="config file not found"):
        find_config("configs/nope.yaml")


# --------------------------------------------------------------------------- one default, everywhere


def _subparser(name):
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sub.choices[name]


#: The module that declares each command's options (its ``_models()``; the executor options of the commands that
#: fan out work come from the config's executor settings: topomatch.cli.common.add_executor_options).
OPTION_MODULES = {"skeleton": "topomatch.cli.skeleton", "register": "topomatch.cli.registration",
                  "match": "topomatch.cli.retrieval", "query": "topomatch.cli.retrieval",
                  "evaluate": "topomatch.cli.retrieval", "index": "topomatch.cli.retrieval",
                  "run": "topomatch.cli.engine", "validate": "topomatch.cli.engine"}


@pytest.mark.parametrize("command", sorted(OPTION_MODULES))
def test_cli_options_show_the_model_defaults_and_set_nothing_unless_given(command):
    from topomatch.pipeline.config import ExecutorConfig

    models = {**getattr(importlib.import_module(OPTION_MODULES[command]), "_models", dict)(),
              "executor": ExecutorConfig}
    generated = [a for a in _subparser(command)._actions if a.dest.startswith("opt__")]
    assert generated
    for action in generated:
        path = action.dest.removeprefix("opt__").replace("__", ".")
        info, _ = field_of(models, path)
        default = info.get_default(call_default_factory=True)
        if default is not None and str(default) != "PydanticUndefined":
            assert f"(default: {default})" in action.help, (path, action.help)
        assert action.default is argparse.SUPPRESS, path  # left out, the model's default applies


def test_retrieval_defaults_are_the_catalogue_best():
    from topomatch.retrieval import Collection, index, match
    from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, DEFAULT_PAIR_METHOD

    for command in ("index", "query", "evaluate"):
        method = next(a for a in _subparser(command)._actions if a.dest == "method")
        assert method.default == DEFAULT_METHOD
    assert next(a for a in _subparser("match")._actions if a.dest == "method").default == DEFAULT_PAIR_METHOD
    assert inspect.signature(index).parameters["method"].default == DEFAULT_METHOD
    assert inspect.signature(Collection.query).parameters["method"].default == DEFAULT_METHOD
    assert inspect.signature(match).parameters["method"].default == DEFAULT_PAIR_METHOD


def test_bad_match_options_are_config_errors_naming_them():
    """The API's ``options`` are checked as the CLI's: a ConfigError naming each bad one, before any mesh is read."""
    for options, words in (({"unmatched_cost": -1}, "options.unmatched_cost: Input should be greater than or equal to 0"),
                           ({"bogus": 1}, "options.bogus: unknown key")):
        with pytest.raises(topomatch.ConfigError, match=words):
            topomatch.match("no_such_a.off", "no_such_b.off", method="srg", options=options)


def test_unmatched_cost_default_is_the_methods_own():
    from topomatch.stages.retrieval.catalogue import METHODS

    for m in METHODS.values():
        if m.kind == "endpoints":
            assert m.match_options().unmatched_cost == m.unmatched_cost > 0
            assert m.match_options(unmatched_cost=None).unmatched_cost == m.unmatched_cost


def test_skeleton_default_function_is_the_morse_stage_default(capsys):
    from topomatch.stages.morse.stage import MorseParams

    default = MorseParams().function
    api = topomatch.skeleton(BUNDLED_MESHES / "torus.off")
    cli = cli_json(capsys, "skeleton", BUNDLED_MESHES / "torus.off")
    assert api.function == cli["function"] == default


def test_a_script_without_a_main_guard_can_use_the_worker_pool(tmp_path):
    """multiprocessing's workers re-run the parent's script unless it is guarded; the API hides it."""
    script = tmp_path / "script.py"
    paths = [str(BUNDLED_MESHES / n) for n in ("torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz")]
    script.write_text(f"import topomatch\nprint('start')\n"
                      f"r = topomatch.index({paths!r}, {str(tmp_path / 's.db')!r}, method='d2', workers=2)\n"
                      f"print('indexed', r.parts[0].done)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split("\n")[:2] == ["start", "indexed 3"]


def _pd_pair():
    return (topomatch.read_image(ITK_DIR / "BrainProtonDensitySlice.png"),
            topomatch.read_image(ITK_DIR / "BrainProtonDensitySliceR10X13Y17.png"))


@pytest.mark.parametrize("case, message", [
    ("array", "the fixed image must be a file path or an Image, not ndarray: wrap an array as topomatch.Image"),
    ("list", "the fixed image must be a file path or an Image, not list"),
    ("nan", "the moving image 'holes': 4873 of 56797 pixels are NaN or infinite"),
    ("empty", "the fixed image: image is empty (shape (0, 0))"),
    ("thin", "the fixed image: image is too small to register (shape (3, 50)"),
    ("origin", "the fixed image: origin (1e+20, 1e+20) is not finite or lies beyond 1e9 mm"),
    ("spacing", "the moving image: pixel spacing 1e-07, 1e-07 mm: every spacing must be a finite number from 1e-6"),
])
def test_register_checks_images_in_memory_as_it_checks_files(case, message):
    """An Image gets the checks a file gets (NaN, empty, too small, absurd geometry), and anything that is neither a
    path nor an Image is refused by name, instead of an internal error from inside the registration."""
    from topomatch.pipeline.errors import InputError

    f, m = _pd_pair()
    rows = np.arange(150.0)[:, None] + np.arange(50.0)
    fixed, moving = {
        "array": (f.data, m.data), "list": ([1, 2], m),
        "nan": (f, topomatch.Image(np.where(m.data > 200, np.nan, m.data), name="holes")),
        "empty": (topomatch.Image(np.zeros((0, 0)), name=""), m),
        "thin": (topomatch.Image(rows[:3], name=""), topomatch.Image(rows[:3])),
        "origin": (topomatch.Image(f.data, origin=(1e20, 1e20), name=""), m),
        "spacing": (f, topomatch.Image(m.data, spacing=(1e-7, 1e-7), name="")),
    }[case]
    with pytest.raises(InputError) as info:
        topomatch.register(fixed, moving)
    assert message in str(info.value)


def test_register_keeps_precision_in_small_units_and_writes_strict_json(tmp_path):
    """At 1e-6 mm pixels the translation keeps its significant digits (it was rounded to 6 decimals: 0); numpy
    scalars are accepted as options; an undefined measure (no overlap) is null, never -Infinity, in the result and
    in registration.json."""
    f, m = _pd_pair()
    micro = topomatch.register(topomatch.Image(f.data, spacing=(1e-6, 1e-6)),
                               topomatch.Image(m.data, spacing=(1e-6, 1e-6)), seed=np.int64(0), alpha=np.float64(2))
    unit = topomatch.register(f, m)
    assert micro.ok and unit.ok
    np.testing.assert_allclose(np.asarray(micro.translation) * 1e6, unit.translation, atol=0.05)
    np.testing.assert_allclose(micro.parameters[1:], np.asarray(micro.translation), rtol=1e-9)
    crop = topomatch.register(f, topomatch.Image(m.data[100:120, 100:120], name="crop"))
    assert crop.to_dict()["objective"] is None and not crop.ok
    json.dumps(crop.to_dict(), allow_nan=False)
    topomatch.write_registration_files(crop, tmp_path)
    json.loads((tmp_path / "registration.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in JSON"))


def test_a_folder_without_a_dicom_series_is_named_once_and_quietly(tmp_path, capfd):
    """A folder given with a trailing slash was named twice (the pair's label, then the reader's message), and GDCM
    printed a warning of its own to stderr."""
    import shutil

    from topomatch.pipeline.errors import InputError

    shutil.copy(ITK_DIR / "BrainT1Slice.png", tmp_path)
    with pytest.raises(InputError) as info:
        topomatch.register(f"{tmp_path}/", ITK_DIR / "BrainT1Slice.png")
    assert str(info.value) == f"{tmp_path}: is a folder without a DICOM series; give a DICOM series folder or an image file"
    assert "No Series were found" not in capfd.readouterr().err


def test_the_overlay_draws_large_images_block_averaged_and_small_ones_as_they_are(tmp_path, monkeypatch):
    """A hostile user's 3,000-pixel section took 12 s and 1.8 GB to write with --out, most of it drawing the overlay at
    full resolution: the figure now gets each image block-averaged to at most OVERLAY_PIXELS an axis (the factor the
    ceiling of size / OVERLAY_PIXELS), in the same physical place; an image within it is drawn as it is."""
    import topomatch.registration as api
    from topomatch.stages.registration import reports

    drawn = []
    original = reports.overlay_figure
    monkeypatch.setattr(reports, "overlay_figure", lambda pairs, **kw: drawn.append(pairs[0][:2]) or original(pairs, **kw))
    monkeypatch.setattr(api, "OVERLAY_PIXELS", 100)
    small = topomatch.Image(np.add.outer(np.arange(90.0), np.arange(80.0)), name="small")
    large = topomatch.Image(np.add.outer(np.arange(250.0), np.arange(210.0)) % 37.0, name="large")
    for image in (small, large):
        api.write_registration_files(topomatch.register(image, image), tmp_path / image.name)
    (fs, ms), (fl, ml) = drawn
    assert fs is small and ms is small  # within the limit: the image itself
    assert fl.shape == ml.shape == (83, 70) and fl.spacing == (3.0, 3.0)  # 250 // 3 rows, 210 // 3 columns
    np.testing.assert_allclose(fl.data[0, 0], large.data[:3, :3].mean())
    np.testing.assert_allclose(fl.physical(np.zeros((1, 2))), [[1.0, 1.0]])  # the first block's centre


def test_an_output_folder_reused_for_another_format_warns_of_the_older_files(tmp_path):
    """A hostile user's pass: --out reused for a run that writes another format kept the earlier run's resampled image
    beside the new one without a word. Now it warns, naming them (the command does not delete files it did not write);
    the same format written again replaces its files and says nothing."""
    import warnings

    pair = (ITK_DIR / "BrainProtonDensitySliceBorder20.png", ITK_DIR / "BrainProtonDensitySliceShifted13x17y.png")
    outcome = topomatch.register(*pair)
    topomatch.write_registration_files(outcome, tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        topomatch.write_registration_files(outcome, tmp_path)  # the same files again: no warning
    in_memory = topomatch.register(topomatch.read_image(pair[0]), topomatch.read_image(pair[1]))  # written as .nii.gz
    with pytest.warns(UserWarning, match=r"moving_resampled.png, moving_resampled.tif from an earlier run .*this run "
                                         r"wrote moving_resampled.nii.gz"):
        topomatch.write_registration_files(in_memory, tmp_path)
    assert (tmp_path / "moving_resampled.png").exists() and (tmp_path / "moving_resampled.nii.gz").exists()
