"""The run page and report outputs: numbers for readers, headings from report names, a summary with
timings and failures, scrolling tables, figures in every configured format at the configured dpi,
and axis labels with names and units."""

from __future__ import annotations

import re

import pytest

from topomatch.pipeline.config import build_experiment
from topomatch.pipeline.reports import format_number, html_table, humanise
from topomatch.pipeline.runner import run_experiment


@pytest.mark.parametrize("value,scale,text", [
    (1.8083e-16, 9.8, "0"),            # rounding noise next to values near 10
    (1.8083e-16, None, "1.808e-16"),   # alone it is what it is
    (0.0, None, "0"),
    (9.82346, None, "9.823"),
    (1234.5678, None, "1235"),
    (0.0123456, None, "0.01235"),
    (12.0, None, "12"),
    (2.5e7, None, "2.5e7"),
    (-0.000123456, None, "-1.235e-4"),
    (float("nan"), None, "nan"),
])
def test_format_number(value, scale, text):
    assert format_number(value, scale) == text


def test_html_table_scrolls_and_formats_per_column():
    rows = [{"item": "a", "x": 1.8083e-16, "n": 3}, {"item": "b", "x": 0.5, "n": 12}]
    out = html_table(rows)
    assert out.startswith("<div class='scroll'>") and "e-16" not in out
    assert "<td class='num'>0</td>" in out and "<td class='num'>0.5</td>" in out and "<td class='num'>12</td>" in out
    assert humanise("skeleton_vs_noise") == "Skeleton vs noise"


def test_run_page_summary_headings_figure_formats_and_labels(small_config, tmp_path):
    small_config["stages"][2]["noise"]["seed"] = 3
    small_config["inputs"]["meshes"].append(str(tmp_path / "broken.off"))
    (tmp_path / "broken.off").write_text("OFF\n3 1 0\n0 0 0\n")
    small_config["reports"] = [
        {"table": {"name": "areas", "columns": ["item", "measures.area", "noise.*"]}},
        {"line_plot": {"name": "area_vs_noise", "x": "noise.sigma", "y": ["measures.area"]}},
    ]
    small_config["figure_format"] = ["png", "svg", "pdf"]
    small_config["dpi"] = 200
    outcome = run_experiment(build_experiment(small_config), out_root=tmp_path / "runs", progress=False)
    d = outcome.run_dir
    for fmt in ("png", "svg", "pdf"):
        assert (d / "figures" / f"area_vs_noise.{fmt}").stat().st_size > 1000
    from PIL import Image

    assert Image.open(d / "figures" / "area_vs_noise.png").info["dpi"][0] == pytest.approx(200, abs=1)
    svg = (d / "figures" / "area_vs_noise.svg").read_text()
    assert "surface area (mesh units²)" in svg and "vertex noise σ (× bounding-box diagonal)" in svg
    assert "noise.sigma" not in svg and "measures.area" not in svg
    page = (d / "index.html").read_text()
    summary = page[page.index("<dl class='summary'>"):page.index("</dl>")]
    assert "2 of 6 items failed" in summary and "s computing" in summary and "load &rarr; clean" in summary
    assert "<h2 id='r1'>Areas <span class='kind'>(table)</span></h2>" in page
    assert "<h2 id='r2'>Area vs noise <span class='kind'>(line_plot)</span></h2>" in page
    assert "<figcaption>Figure 1: Area vs noise." in page and "figures/area_vs_noise.pdf" in page
    assert "broken.off" in page[page.index("Failed items"):]
    assert not re.search(r"\d\.\d{4,}e-\d\d", page)  # no unformatted floats such as 1.8083e-16


def test_line_plot_draws_one_line_per_value_of_the_other_sweep_keys(small_config, tmp_path):
    # a grid over noise.sigma x noise.seed: a line per input and seed, each told apart (they were merged into one
    # line per input, jumping between the seeds), with ticks at the swept values
    from topomatch.pipeline.builtin_reports import line_plot_report
    from topomatch.pipeline.registry import get_report

    small_config["sweep"] = {"noise.sigma": [0.0, 0.001, 0.002, 0.004], "noise.seed": [1, 2]}
    small_config["sweep_mode"] = "grid"
    experiment = build_experiment(small_config)
    outcome = run_experiment(experiment, out_root=tmp_path / "runs", progress=False)
    params = get_report("line_plot").params.model_validate({"name": "a", "x": "noise.sigma", "y": ["measures.area"]})
    fig = line_plot_report(experiment, outcome.items, params).figures["a"]
    ax = fig.axes[0]
    labels = [line.get_label() for line in ax.get_lines()]
    assert len(labels) == 2 * len(experiment.inputs) and len(set(labels)) == len(labels)
    assert all(len(line.get_xdata()) == 4 for line in ax.get_lines())
    assert len({(line.get_color(), line.get_linestyle()) for line in ax.get_lines()}) == len(labels)
    assert [t.get_text() for t in ax.get_xticklabels()] == ["0", "0.001", "0.002", "0.004"]
