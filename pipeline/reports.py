"""Running a run's reports and writing what they return: tables (CSV + JSON), figures (PNG), the run page.

A report is a function ``func(experiment, results, params) -> ReportOutput`` marked with
:func:`~topomatch.pipeline.contract.report` (the engine's own are in
:mod:`topomatch.pipeline.builtin_reports`, the domains' in ``topomatch.stages.<domain>.reports``).
Every run also writes ``tables/results.csv`` (one row per item) and ``index.html``.
"""

from __future__ import annotations

import csv
import html
import io
import json
import math
from pathlib import Path
from typing import Any

from topomatch.pipeline.contract import ReportOutput
from topomatch.pipeline.files import atomic_write_bytes, atomic_write_text
from topomatch.pipeline.registry import get_report


# --------------------------------------------------------------------------- running and writing


def run_reports(experiment, results) -> dict[str, ReportOutput | str]:
    """Run each configured report; a failing report is recorded as its error message."""
    import matplotlib

    matplotlib.use("Agg")
    outputs: dict[str, ReportOutput | str] = {}
    for call in experiment.reports:
        spec = get_report(call.name)
        label = call.name if call.name not in outputs else f"{call.name}#{call.index}"
        try:
            outputs[label] = spec.func(experiment, results, call.params)
        except Exception as exc:  # keep the other reports and the computed results
            outputs[label] = f"report {label} failed: {type(exc).__name__}: {exc}"
    return outputs


def _cell(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, (list, tuple, dict)):
        return json.dumps(value, default=str)
    return value


def write_table(folder: Path, name: str, rows: list[dict[str, Any]]) -> list[str]:
    """Write ``rows`` as ``name.csv`` and ``name.json``; return the two paths."""
    columns: list[str] = []
    for row in rows:
        columns.extend(c for c in row if c not in columns)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({c: _cell(row.get(c, "")) for c in columns})
    atomic_write_text(folder / f"{name}.csv", buf.getvalue())
    atomic_write_text(folder / f"{name}.json", json.dumps(rows, indent=1, default=str))
    return [str(folder / f"{name}.csv"), str(folder / f"{name}.json")]


def write_report_outputs(run_dir: Path, outputs: dict[str, ReportOutput | str]) -> dict[str, list[str]]:
    """Write every table and figure; return {report label: [relative paths or error]}."""
    import matplotlib.pyplot as plt

    written: dict[str, list[str]] = {}
    for label, out in outputs.items():
        if isinstance(out, str):
            written[label] = [f"ERROR: {out}"]
            continue
        paths = []
        for name, rows in out.tables.items():
            paths += [str(Path(p).relative_to(run_dir)) for p in write_table(run_dir / "tables", name, rows)]
        for name, fig in out.figures.items():
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
            plt.close(fig)
            atomic_write_bytes(run_dir / "figures" / f"{name}.png", buf.getvalue())
            paths.append(f"figures/{name}.png")
        paths += [f"NOTE: {n}" for n in out.notes]
        written[label] = paths
    return written


def _html_table(rows: list[dict[str, Any]], limit: int = 200) -> str:
    if not rows:
        return "<p><em>empty</em></p>"
    columns: list[str] = []
    for row in rows:
        columns.extend(c for c in row if c not in columns)

    def fmt(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.6g}"
        return html.escape(str(_cell(v)))

    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{fmt(r.get(c, ''))}</td>" for c in columns) + "</tr>" for r in rows[:limit]
    )
    more = f"<p>... {len(rows) - limit} more rows in the CSV</p>" if len(rows) > limit else ""
    return f"<table><tr>{head}</tr>{body}</table>{more}"


def write_index_html(run_dir: Path, experiment, results, manifest: dict, written: dict[str, list[str]]) -> None:
    """A single page with the run's summary, figures and tables."""
    esc = html.escape
    parts = [
        "<!doctype html><meta charset='utf-8'>",
        f"<title>{esc(experiment.name)}</title>",
        "<style>body{font-family:sans-serif;margin:2em;max-width:1400px}table{border-collapse:collapse;"
        "font-size:12px}td,th{border:1px solid #ccc;padding:2px 6px}img{max-width:100%;border:1px solid #eee}"
        ".err{color:#b00}</style>",
        f"<h1>{esc(experiment.name)}</h1><p>{esc(experiment.raw.description)}</p>",
        f"<p>{manifest['n_items']} items, {manifest['n_failed']} failed; compute {manifest['seconds']['compute']:.2f} s; "
        f"cache hits {manifest['cache']['hits']}/{manifest['cache']['stage_results']}; config hash "
        f"<code>{manifest['config_hash']}</code>. <a href='config.yaml'>config</a> · "
        f"<a href='manifest.json'>manifest</a> · <a href='tables/results.csv'>results.csv</a></p>",
    ]
    failed = [r for r in results if not r.ok]
    if failed:
        parts.append("<h2>Failed items</h2><ul>" + "".join(f"<li class='err'>{esc(r.error or '')}</li>" for r in failed) + "</ul>")
    for label, paths in written.items():
        parts.append(f"<h2>{esc(label)}</h2>")
        for p in paths:
            if p.startswith("ERROR: "):
                parts.append(f"<p class='err'>{esc(p)}</p>")
            elif p.startswith("NOTE: "):
                parts.append(f"<p>{esc(p[6:])}</p>")
            elif p.endswith(".png"):
                parts.append(f"<p><img src='{esc(p)}' alt='{esc(p)}'></p>")
            elif p.endswith(".csv"):
                rows = json.loads((run_dir / p.replace(".csv", ".json")).read_text())
                parts.append(f"<h3><a href='{esc(p)}'>{esc(Path(p).name)}</a></h3>" + _html_table(rows))
    parts.append("<h2>All items</h2>" + _html_table([r.row() for r in results]))
    atomic_write_text(run_dir / "index.html", "\n".join(parts))
