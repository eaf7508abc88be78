"""The engine's own reports, for any kind of item: ``table`` and ``line_plot``.

- ``table``: selected columns of the results table (``columns`` are glob patterns).
- ``line_plot``: a column against a sweep key or another column, one line per input.
"""

from __future__ import annotations

import fnmatch
import json
from pathlib import Path
from typing import Any

from pydantic import Field

from topomatch.pipeline.contract import (ConfigError, Params, ReportOutput, axis_label, report, series_style,
                                        sweep_ticks, sweep_value_labels)

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
    if rows and not any(rows):  # every row empty: no column matched (a table of blank lines said nothing)
        raise ConfigError(f"table {params.name}: the columns {params.columns} match no results column")
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
    title: str = Field("", description="figure title (default: the y quantities against the x quantity)")
    xlabel: str = Field("", description="x-axis label (default: the sweep key's or column's name and unit)")
    ylabels: list[str] = Field(default_factory=list, description="y-axis labels, one per y (default: names and units)")


@report("line_plot", params=LinePlotParams)
def line_plot_report(experiment, results, params: LinePlotParams) -> ReportOutput:
    """A results column against a sweep key or column, one line per input."""
    import matplotlib.pyplot as plt

    if params.ylabels and len(params.ylabels) != len(params.y):
        raise ConfigError(f"line_plot {params.name}: {len(params.ylabels)} ylabels for {len(params.y)} y columns")
    rows = [r.row() for r in results if r.ok]
    xlabel = params.xlabel or axis_label(experiment, results, params.x)
    fig, axes = plt.subplots(1, len(params.y), figsize=(4.6 * len(params.y), 3.6), squeeze=False)
    names = []
    for i, (ax, y) in enumerate(zip(axes[0], params.y)):
        groups: dict[str, list[tuple[float, float]]] = {}
        for row in rows:
            if params.x in row and y in row:  # one line per input and value of every other sweep key
                group = " ".join([Path(str(row.get(params.group_by, ""))).name]
                                 + sweep_value_labels(experiment, row, skip=(params.x,)))
                groups.setdefault(group, []).append((float(row[params.x]), float(row[y])))
        if not groups:
            raise ConfigError(f"line_plot: no rows have both {params.x!r} and {y!r}")
        for j, (group, pts) in enumerate(groups.items()):
            pts.sort()
            if params.normalize and pts[0][1] == 0:
                raise ConfigError(f"line_plot {params.name}: cannot normalise {y!r} by its value 0 at {params.x}={pts[0][0]}")
            scale = pts[0][1] if params.normalize else 1.0
            ax.plot([p[0] for p in pts], [p[1] / scale for p in pts], label=group, **series_style(j))
        if not params.logx:
            sweep_ticks(ax, [p[0] for pts in groups.values() for p in pts])
        name = params.ylabels[i] if params.ylabels else axis_label(experiment, results, y)
        names.append(name.split(" (")[0])
        if params.normalize and not params.ylabels:
            name = f"{name.split(' (')[0]}\nrelative to its value at {pts[0][0]:g}"
        ax.set_xlabel(xlabel)
        ax.set_ylabel(name)
        if params.logx:
            ax.set_xscale("symlog", linthresh=1e-4)
        ax.grid(alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    title = params.title or f"{' and '.join(names)} against {xlabel.split(' (')[0]}"
    fig.suptitle(title[:1].upper() + title[1:], fontsize=11)
    fig.tight_layout()
    # one legend for all panels, beside them, so that it hides no data
    fig.legend(handles, labels, loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8, frameon=False)
    return ReportOutput(figures={params.name: fig})
