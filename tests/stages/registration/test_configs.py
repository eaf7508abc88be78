"""The registration configs run end to end (reduced where they are large)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from topomatch.pipeline.config import load_experiment
from topomatch.pipeline.runner import run_experiment
from tests_paths import REPO_ROOT

CONFIGS = REPO_ROOT / "configs" / "registration"


def _run(path: Path, tmp_path: Path, overrides=()):
    experiment = load_experiment(path, overrides=["executor.workers=1", *overrides])
    return run_experiment(experiment, out_root=tmp_path / "runs", progress=False)


def test_demo_config(tmp_path):
    outcome = _run(CONFIGS / "demo.yaml", tmp_path)
    assert not outcome.failed
    rows = json.loads((outcome.run_dir / "tables" / "registration.json").read_text())
    assert rows[0]["tre_mean"] < 0.1 and rows[0]["ok"]
    assert (outcome.run_dir / "figures" / "registration_overlay.png").exists()


def test_analytic_figure_configs(tmp_path):
    outcome = _run(CONFIGS / "entropy_bernoulli.yaml", tmp_path)
    rows = json.loads((outcome.run_dir / "tables" / "fig2_2_tsallis_entropy.json").read_text())
    for r in rows:
        assert r["max"] == pytest.approx(r["max_exact"], rel=1e-9) and r["argmax_p"] == pytest.approx(0.5)
    jt = json.loads((outcome.run_dir / "tables" / "fig2_3_jensen_tsallis.json").read_text())
    assert all(r["min_on_diagonal"] < 1e-12 for r in jt)  # JT = 0 where p = q
    assert {(r["at_p"], r["at_q"]) for r in jt} <= {(0.0, 1.0), (1.0, 0.0)}  # largest for opposite one-hots
    outcome = _run(CONFIGS / "conditionals.yaml", tmp_path)
    rows = json.loads((outcome.run_dir / "tables" / "fig2_4_conditionals.json").read_text())
    aligned = [r for r in rows if (r["tx"], r["ty"], r["angle"]) == (0, 0, 0)]
    moved = [r for r in rows if (r["tx"], r["ty"], r["angle"]) != (0, 0, 0)]
    assert all(r["mean_row_max"] == pytest.approx(1.0) for r in aligned)  # crisp: one-hot rows
    assert max(r["jt"] for r in moved) < min(r["jt"] for r in aligned)


def test_recovery_config_reduced(tmp_path):
    outcome = _run(CONFIGS / "recovery.yaml", tmp_path, ["sweep.misalign.theta=[[10, 20, 20]]",
                                                          "sweep.register.metric.name=[jt, mi]",
                                                          "sweep.register.seed=[0, 1]"])
    assert not outcome.failed and len(outcome.items) == 12
    rows = json.loads((outcome.run_dir / "tables" / "fig2_6_to_2_8.json").read_text())
    assert {r["method"].split("/")[1][:2] for r in rows} == {"jt", "mi"}
    assert len(rows) == 12 and {r["seed"] for r in rows} == {0, 1}  # one row per run: the bars' range is real
    assert all(r["tre_mean"] < 0.5 for r in rows if r["method"].startswith("spsa/jt"))
    assert len(list((outcome.run_dir / "figures").glob("fig2_6_to_2_8_*.png"))) == 3


def test_landscape_configs_reduced(tmp_path):
    outcome = _run(CONFIGS / "landscapes.yaml", tmp_path, ["landscape.points=9"])
    assert not outcome.failed
    for name in ("fig2_9_jt_uniform", "fig2_10_jr_uniform", "fig2_11_jt_histogram", "fig2_12_jr_histogram"):
        assert (outcome.run_dir / "figures" / f"{name}.png").exists()  # the thesis's four figures, its numbering
    rows = json.loads((outcome.run_dir / "tables" / "fig2_11_jt_histogram.json").read_text())
    assert all(r["peak_at"] == 0 for r in rows) and {r["measure"] for r in rows} == {"jt, histogram weights"}
    self_pair = [r for r in json.loads((outcome.run_dir / "tables" / "fig2_10_jr_uniform.json").read_text())
                 if r["input"].split("|")[0] == r["input"].split("|")[1]]
    # an image with itself, uniform weights: the aligned JR is the Rényi entropy of the uniform mixture over the
    # occupied bins, log(32) for every alpha (why docs/thesis.md does not count it as evidence)
    assert all(r["max"] == pytest.approx(np.log(32), rel=1e-9) for r in self_pair)
    outcome = _run(CONFIGS / "mri_volume_alpha.yaml", tmp_path, ["landscape.points=7"])
    assert not outcome.failed and (outcome.run_dir / "figures" / "slices_registered.png").exists()
    slices = json.loads((outcome.run_dir / "tables" / "slices.json").read_text())
    assert all(r["true_angle"] == 10 and r["tre_mean"] < 2.0 for r in slices)  # moved by a known transform, found


def test_accuracy_sweep_config_reduced(tmp_path):
    outcome = _run(CONFIGS / "accuracy_sweep.yaml", tmp_path, ["sweep.misalign_pair.index=[0]",
                                                                "sweep.register.metric.name=[jt, mi]"])
    assert not outcome.failed and len(outcome.items) == 4
    rows = json.loads((outcome.run_dir / "tables" / "accuracy.json").read_text())
    overall = {r["method"]: r for r in rows if r["pairs"] == "all"}
    assert set(overall) == {"spsa/jt(alpha=2 histogram)", "spsa/mi", "simpleitk/mattes(regular_step)",
                            "simpleitk/mattes(line_search)"}
    assert overall["spsa/jt(alpha=2 histogram)"]["success_rate"] == 1.0
    assert all(r["cases"] == 2 for r in overall.values())  # SimpleITK runs once per case, not per metric


def test_itk_configs_validate_and_name_their_cases():
    experiment = load_experiment(CONFIGS / "itk_cases.yaml")
    assert len(experiment.inputs) == 5  # the S12 row has no consensus and is left out
    assert all(u.values["truth"] and set(u.values["truth"]) == {"tx", "ty", "angle"} for u in experiment.inputs)
    assert len(load_experiment(CONFIGS / "simpleitk_reference.yaml").items()) == 5


def test_volumes_3d_config_reduced(tmp_path):
    # SimpleITK reduced to its coarsest level (its accuracy is the benchmark's business)
    outcome = _run(CONFIGS / "volumes_3d.yaml", tmp_path, ["sweep.misalign.index=[0]",
                                                            "sweep.misalign.contrast=[t2_like]",
                                                            "register_sitk_3d.shrink=[4]",
                                                            "register_sitk_3d.smoothing=[2.0]"])
    assert not outcome.failed and len(outcome.items) == 1
    rows = json.loads((outcome.run_dir / "tables" / "cases.json").read_text())
    assert {r["method"] for r in rows} == {"spsa/jt(alpha=2 histogram)", "simpleitk/mattes(regular_step)"}
    ours = next(r for r in rows if r["method"].startswith("spsa"))
    assert ours["tre_mean"] < 1.0 and ours["ok"] and {"angle_x", "tz", "true_angle_z"} <= set(ours)


def test_a_pair_can_be_named():
    # two slices of one file would otherwise read "X|X" on every panel (thesis Figs. 2.13-2.15)
    experiment = load_experiment(CONFIGS / "mri_volume_alpha.yaml")
    assert [u.label for u in experiment.inputs] == ["T1 slice 30|T1 slice 31"]
    assert all(i.item_id.startswith("T1 slice 30|T1 slice 31[") for i in experiment.items())
