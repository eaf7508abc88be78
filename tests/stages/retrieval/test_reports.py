"""The retrieval_benchmark and retrieval_robustness reports on bundled meshes (d2 + ShapeDNA, and their fusion)."""

from __future__ import annotations

import json

import pytest

from topomatch.pipeline.config import build_experiment
from topomatch.pipeline.runner import run_experiment
from tests_paths import BUNDLED_MESHES

LABELS = {"torus.off": "handles", "eight_genus2.off": "handles", "odedstein_hand_lowres.obj.gz": "handles",
          "odedstein_human_man.obj.gz": "body", "odedstein_human_woman.obj.gz": "body",
          "odedstein_hand_closed.obj.gz": "body"}
METHODS = {"d2": "d2", "shapedna": "shapedna"}


@pytest.fixture
def labels_csv(tmp_path):
    out = tmp_path / "labels.csv"
    out.write_text("relative_path,class\n" + "".join(f"{BUNDLED_MESHES / k},{v}\n" for k, v in LABELS.items()))
    return out


def config(labels_csv, reports, **extra):
    return {"name": "retrieval-test", "inputs": {"meshes": [str(BUNDLED_MESHES / k) for k in LABELS]},
            "stages": ["load", {"clean": {"components": "largest"}}, {"transform": {}}, "d2",
                       {"shapedna": {"k": 20}}],
            "reports": reports, **extra}


def tables(outcome, name):
    return json.loads((outcome.run_dir / "tables" / f"{name}.json").read_text())


def test_benchmark_report_with_a_fusion(labels_csv, tmp_path):
    cfg = config(labels_csv, [{"retrieval_benchmark": {"name": "b", "labels": str(labels_csv), "methods": METHODS,
                                                       "extra_fusions": {"both": ["d2", "shapedna"]}, "rerank_k": 2,
                                                       "thumbnails": False, "table_classes": ["handles", "body"],
                                                       "queries": []}}])
    outcome = run_experiment(build_experiment(cfg), out_root=tmp_path / "runs", progress=False)
    metrics = tables(outcome, "b_metrics")
    assert {r["method"] for r in metrics} == {"d2", "shapedna", "both"}
    assert all(r["n"] == 6 and 0 <= r["map"] <= 1 for r in metrics)
    ablation = {r["fusion"] for r in tables(outcome, "b_ablation")}
    assert ablation == {"both", "both (no re-ranking)", "both without d2", "both without shapedna"}
    assert (outcome.run_dir / "figures" / "b_pr.png").is_file()


def test_robustness_report_rotated_and_scaled_queries_find_their_original(labels_csv, tmp_path):
    cfg = config(labels_csv, [{"retrieval_robustness": {"name": "r", "labels": str(labels_csv), "methods": METHODS,
                                                        "extra_fusions": {"both": ["d2", "shapedna"]}, "rerank_k": 2}}],
                 sweep={"transform.angle_deg": [0.0, 75.0], "transform.scale": [1.0, 3.0]},
                 sweep_mode="one_at_a_time")
    outcome = run_experiment(build_experiment(cfg), out_root=tmp_path / "runs", progress=False)
    rows = tables(outcome, "r_metrics")
    assert {r["perturbation"] for r in rows} == {"clean", "transform.angle_deg=75.0",
                                                 "transform.scale=3.0"}
    # D2 (normalised by its mean distance) and ShapeDNA (lambda A / i) are similarity invariants:
    # a rotated or scaled copy is nearest to its own original
    assert all(r["self@1"] == 1.0 and r["n"] == 6 for r in rows)
    assert all(r["class_queries"] == 6 for r in rows)  # two classes of three: PSB evaluates every query
    assert (outcome.run_dir / "figures" / "r_metrics.png").is_file()
