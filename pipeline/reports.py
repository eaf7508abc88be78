"""Reports: tables and figures computed from the items of a run, and the run page.

A report is a function ``func(experiment, results, params) -> ReportOutput``
registered with :func:`report`. Built in here:

- ``table``: selected columns of the results table (``columns`` are glob patterns).
- ``line_plot``: a column against a sweep key or another column, one line per input.
- ``mesh_gallery``: the final mesh of every item, rendered (rows = inputs,
  columns = sweep points).

Every run also writes ``tables/results.csv`` (one row per item) and
``index.html``.
"""

from __future__ import annotations

import csv
import fnmatch
import html
import io
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal

from pydantic import Field

from topomatch.pipeline.cache import atomic_write_bytes, atomic_write_text
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.params import Params


@dataclass
class ReportOutput:
    """Tables (name -> rows) and figures (name -> matplotlib Figure) of one report."""

    tables: dict[str, list[dict[str, Any]]] = field(default_factory=dict)
    figures: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class ReportSpec:
    name: str
    func: Callable[..., ReportOutput]
    params: type[Params]
    doc: str


REPORTS: dict[str, ReportSpec] = {}


def report(name: str, *, params: type[Params]) -> Callable:
    """Register a report function under ``name`` (decorator)."""

    def register(func: Callable[..., ReportOutput]) -> Callable[..., ReportOutput]:
        doc = (func.__doc__ or "").strip().splitlines()[0] if func.__doc__ else ""
        REPORTS[name] = ReportSpec(name, func, params, doc)
        return func

    return register


def get_report(name: str) -> ReportSpec:
    from topomatch.pipeline.registry import discover

    discover()
    try:
        return REPORTS[name]
    except KeyError:
        raise ConfigError(f"unknown report {name!r}; known reports: {', '.join(sorted(REPORTS))}") from None


# --------------------------------------------------------------------------- running and writing


def run_reports(experiment, results) -> dict[str, ReportOutput | str]:
    """Run each configured report; a failing report is recorded as its error message."""
    import matplotlib

    matplotlib.use("Agg")
    outputs: dict[str, ReportOutput | str] = {}
    for call in experiment.reports:
        spec = REPORTS[call.name]
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


# --------------------------------------------------------------------------- built-in reports


class TableParams(Params):
    name: str = Field("summary", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the table")
    columns: list[str] = Field(default_factory=lambda: ["*"], description="glob patterns of results columns to keep")
    only_ok: bool = Field(False, description="leave failed items out")
    unique: bool = Field(False, description="drop rows repeated after the column selection")


def select_columns(rows: list[dict[str, Any]], patterns: list[str]) -> list[dict[str, Any]]:
    """Keep the columns matching any pattern, in pattern order."""
    out = []
    for row in rows:
        kept: dict[str, Any] = {}
        for pattern in patterns:
            for column, value in row.items():
                if column not in kept and fnmatch.fnmatchcase(column, pattern):
                    kept[column] = value
        out.append(kept)
    return out


@report("table", params=TableParams)
def table_report(experiment, results, params: TableParams) -> ReportOutput:
    """Selected columns of the results table."""
    rows = select_columns([r.row() for r in results if r.ok or not params.only_ok], params.columns)
    if params.unique:
        seen: set[str] = set()
        rows = [r for r in rows if not (json.dumps(r, sort_keys=True, default=str) in seen
                                        or seen.add(json.dumps(r, sort_keys=True, default=str)))]
    return ReportOutput(tables={params.name: rows})


class LinePlotParams(Params):
    name: str = Field("plot", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure")
    x: str = Field(description="sweep key or results column on the x axis")
    y: list[str] = Field(min_length=1, description="results columns on the y axis (one panel each)")
    group_by: str = Field("input", description="column that separates the lines")
    logx: bool = False
    normalize: bool = Field(False, description="divide each line by its value at the smallest x")
    title: str = ""


@report("line_plot", params=LinePlotParams)
def line_plot_report(experiment, results, params: LinePlotParams) -> ReportOutput:
    """A results column against a sweep key or column, one line per input."""
    import matplotlib.pyplot as plt

    rows = [r.row() for r in results if r.ok]
    fig, axes = plt.subplots(1, len(params.y), figsize=(4.5 * len(params.y), 3.6), squeeze=False)
    for ax, y in zip(axes[0], params.y):
        groups: dict[str, list[tuple[float, float]]] = {}
        for row in rows:
            if params.x in row and y in row:
                group = Path(str(row.get(params.group_by, ""))).name
                groups.setdefault(group, []).append((float(row[params.x]), float(row[y])))
        if not groups:
            raise ConfigError(f"line_plot: no rows have both {params.x!r} and {y!r}")
        for group, pts in groups.items():
            pts.sort()
            if params.normalize and pts[0][1] == 0:
                raise ConfigError(f"line_plot {params.name}: cannot normalise {y!r} by its value 0 at {params.x}={pts[0][0]}")
            scale = pts[0][1] if params.normalize else 1.0
            ax.plot([p[0] for p in pts], [p[1] / scale for p in pts], marker="o", label=group)
        ax.set_xlabel(params.x)
        ax.set_ylabel(f"{y} / value at {params.x.split('.')[-1]}={pts[0][0]:g}" if params.normalize else y)
        if params.logx:
            ax.set_xscale("symlog", linthresh=1e-4)
        ax.grid(alpha=0.3)
    axes[0][-1].legend(fontsize=7, loc="best")
    if params.title:
        fig.suptitle(params.title)
    fig.tight_layout()
    return ReportOutput(figures={params.name: fig})


class MeshGalleryParams(Params):
    name: str = Field("meshes", pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure")
    state: str = Field("mesh", description="state entry to draw (the last value the chain produced)")
    up: Literal["x", "y", "z"] = Field("y", description="the meshes' up axis (most OBJ files: y)")
    elev: float = 15.0
    azim: float = -60.0
    columns: int = Field(5, ge=1, description="panels per row when there is no sweep")
    panel_size: float = Field(2.6, gt=0, description="inches per panel")


def gallery_layout(results, columns: int) -> tuple[int, int, list[int]]:
    """(rows, cols, panel index per result): inputs x sweep points, or wrapped without a sweep."""
    inputs = list(dict.fromkeys(r.input_path for r in results))
    points = list(dict.fromkeys(json.dumps(r.sweep, sort_keys=True) for r in results))
    if len(points) == 1:
        cols = min(columns, len(results))
        return -(-len(results) // cols), cols, list(range(len(results)))
    cells = [inputs.index(r.input_path) * len(points) + points.index(json.dumps(r.sweep, sort_keys=True))
             for r in results]
    return len(inputs), len(points), cells


@report("mesh_gallery", params=MeshGalleryParams)
def mesh_gallery_report(experiment, results, params: MeshGalleryParams) -> ReportOutput:
    """The final mesh of every item (rows: inputs, columns: sweep points)."""
    import matplotlib.pyplot as plt

    from topomatch.pipeline.render import draw_mesh, z_up

    rows, cols, cells = gallery_layout(results, params.columns)
    fig = plt.figure(figsize=(params.panel_size * cols, params.panel_size * rows))
    for r, cell in zip(results, cells):
        ax = fig.add_subplot(rows, cols, cell + 1, projection="3d")
        mesh = r.final(params.state)
        label = Path(r.input_path).name.split(".")[0]
        sweep = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in r.sweep.items())
        if mesh is None:
            ax.set_axis_off()
            ax.set_title(f"{label}\nfailed", fontsize=7, color="#b00")
            continue
        draw_mesh(ax, z_up(mesh, params.up), elev=params.elev, azim=params.azim)
        ax.set_title(f"{label} {sweep}\n{mesh.n_faces} faces", fontsize=7)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0.0, hspace=0.12)
    return ReportOutput(figures={params.name: fig})
