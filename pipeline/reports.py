"""Running a run's reports and writing what they return: tables (CSV + JSON), figures (PNG, SVG,
PDF), files, interactive views, and the run page.

A report is a function ``func(experiment, results, params) -> ReportOutput`` marked with
:func:`~topomatch.pipeline.contract.report` (the engine's own are in
:mod:`topomatch.pipeline.builtin_reports`, the domains' in ``topomatch.stages.<domain>.reports``).
Every run also writes ``tables/results.csv`` (one row per item) and ``index.html``: a summary (what
ran, how long, what failed), then one section per report headed by its title, with captions,
tables that scroll sideways and numbers to four significant digits.
"""

from __future__ import annotations

import csv
import html
import inspect
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from topomatch.pipeline.contract import ReportOutput
from topomatch.pipeline.files import atomic_write_bytes, atomic_write_text
from topomatch.pipeline.registry import get_report

#: Where reports put the scripts their interactive views need; the run page loads each once.
ASSETS_DIR = "assets"

#: Records JavaScript errors on the page (``<html data-js-errors="...">``), for people and for the
#: headless-browser test of the run pages.
_ERROR_HOOK = ("<script>window.addEventListener('error',function(e){var h=document.documentElement;"
               "h.setAttribute('data-js-errors',(h.getAttribute('data-js-errors')||'')+String(e.message)+' | ')});"
               "</script>")


def _view_page(run_dir: Path, name: str, fragment: str) -> str:
    """A standalone page of one interactive view (``views/NAME.html``); the run page inlines the part
    between the view markers."""
    scripts = "".join(f"<script src='../{ASSETS_DIR}/{html.escape(p.name)}'></script>"
                      for p in sorted((run_dir / ASSETS_DIR).glob("*.js")))
    return (f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>{html.escape(name)}</title>"
            f"{_ERROR_HOOK}{scripts}</head><body>\n<!--view-->{fragment}<!--/view-->\n</body></html>")


# --------------------------------------------------------------------------- running and writing


@dataclass(frozen=True)
class WrittenReport:
    """What one report left in the run folder: its files (paths relative to the folder), its notes,
    or the error that stopped it. The manifest stores it as ``{"files": [...], "notes": [...],
    "error": str | null}`` under ``outputs.<label>``."""

    files: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    error: str | None = None

    def to_json(self) -> dict[str, Any]:
        return {"files": list(self.files), "notes": list(self.notes), "error": self.error}

    @classmethod
    def from_json(cls, value: dict[str, Any] | list[str]) -> WrittenReport:
        """A manifest's record; also the list of releases up to 0.1.0 (paths, ``"NOTE: ..."``, ``"ERROR: ..."``)."""
        if isinstance(value, list):
            return cls(tuple(p for p in value if not p.startswith(("NOTE: ", "ERROR: "))),
                       tuple(p[len("NOTE: "):] for p in value if p.startswith("NOTE: ")),
                       next((p[len("ERROR: "):] for p in value if p.startswith("ERROR: ")), None))
        return cls(tuple(value["files"]), tuple(value["notes"]), value["error"])


def report_labels(experiment) -> list[tuple[str, Any]]:
    """(label, call) of each configured report: its name, or ``name#k`` when the name repeats."""
    labels: list[tuple[str, Any]] = []
    for call in experiment.reports:
        taken = {label for label, _ in labels}
        labels.append((call.name if call.name not in taken else f"{call.name}#{call.index}", call))
    return labels


def code_fingerprint() -> str:
    """SHA-256 over the source of the engine and the stages (every report and everything a report imports
    lives there): a report's output is reused only while no code that could draw it has changed."""
    global _FINGERPRINT
    if _FINGERPRINT is None:
        import hashlib
        from importlib.util import find_spec

        # the stages' folder is located, not imported: the engine does not depend on the domains' code
        stages = find_spec("topomatch.stages")
        roots = [Path(__file__).parent, *map(Path, (stages.submodule_search_locations or []) if stages else [])]
        digest = hashlib.sha256()
        for root in roots:
            for path in sorted([*root.rglob("*.py"), *root.rglob("*.c")]):
                digest.update(path.relative_to(root).as_posix().encode())
                digest.update(path.read_bytes())
        _FINGERPRINT = digest.hexdigest()
    return _FINGERPRINT


_FINGERPRINT: str | None = None


def report_key(experiment, label: str, call, results) -> str:
    """What a report's output depends on: its name and parameters, the figure settings, every item's stage
    cache keys and status, and the code (:func:`code_fingerprint`)."""
    import hashlib

    payload = json.dumps([label, call.name, call.params.model_dump(mode="json"), list(experiment.raw.figure_format),
                          experiment.raw.dpi, code_fingerprint(),
                          [(r.item_id, sorted(r.keys.items()), r.ok) for r in results]], sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()


def run_reports(experiment, results, run_dir: Path, *, reuse: dict[str, tuple[str, WrittenReport]] | None = None,
                figure_format: tuple[str, ...] | list[str] = ("png",), dpi: int = 150,
                ) -> tuple[dict[str, WrittenReport], list[str], dict[str, str]]:
    """Run each configured report and write its outputs into ``run_dir`` before the next one runs (one report's
    figures in memory at a time); a failing report is recorded as its error message.

    ``reuse``: {label: (key, what it wrote)} of the run folder's previous manifest; a report whose key is
    unchanged and whose files are all still in ``run_dir`` is not drawn again. Returns ({label: what it wrote},
    the labels reused, {label: key})."""
    import matplotlib

    matplotlib.use("Agg")
    written: dict[str, WrittenReport] = {}
    reused: list[str] = []
    keys: dict[str, str] = {}
    for label, call in report_labels(experiment):
        keys[label] = key = report_key(experiment, label, call, results)
        before = (reuse or {}).get(label)
        if before and before[0] == key and _all_present(run_dir, before[1]):
            written[label] = before[1]
            reused.append(label)
            continue
        spec = get_report(call.name)
        try:
            out = spec.func(experiment, results, call.params)
        except Exception as exc:  # keep the other reports and the computed results
            written[label] = WrittenReport(error=f"report {label} failed: {type(exc).__name__}: {exc}")
            continue
        written[label] = write_report_output(run_dir, label, out, figure_format=figure_format, dpi=dpi)
        del out
    return written, reused, keys


def _all_present(run_dir: Path, record: WrittenReport) -> bool:
    """Whether a report's earlier output is complete: no error, every file there."""
    return record.error is None and all((run_dir / p).is_file() for p in record.files)


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


def _relative_file(run_dir: Path, relative: str) -> Path:
    """``run_dir / relative`` for a file a report returned, refusing paths that leave the run folder."""
    path = (run_dir / relative).resolve()
    if not path.is_relative_to(run_dir.resolve()) or Path(relative).is_absolute():
        raise ValueError(f"a report file must stay inside the run folder, got {relative!r}")
    return path


def write_report_output(run_dir: Path, label: str, out: ReportOutput, *,
                        figure_format: tuple[str, ...] | list[str] = ("png",), dpi: int = 150) -> WrittenReport:
    """Write one report's tables, figures (in each of ``figure_format``, raster ones at ``dpi``; a figure given
    as a function is drawn here, and each figure is closed once written), files and interactive views; return
    what it wrote. A figure that fails to draw is the report's error, the rest is written."""
    import matplotlib.pyplot as plt

    paths, errors = [], []
    for name, rows in out.tables.items():
        paths += [str(Path(p).relative_to(run_dir)) for p in write_table(run_dir / "tables", name, rows)]
    for name in list(out.figures):
        fig = out.figures.pop(name)
        try:
            fig = fig() if callable(fig) else fig
            for fmt in figure_format:
                buf = io.BytesIO()
                fig.savefig(buf, format=fmt, dpi=dpi, bbox_inches="tight")
                atomic_write_bytes(run_dir / "figures" / f"{name}.{fmt}", buf.getvalue())
                paths.append(f"figures/{name}.{fmt}")
        except Exception as exc:  # keep the report's other outputs
            errors.append(f"report {label} failed to draw {name}: {type(exc).__name__}: {exc}")
        finally:
            if not callable(fig):
                plt.close(fig)
    for relative, data in out.files.items():
        atomic_write_bytes(_relative_file(run_dir, relative), data)
        if not relative.startswith(f"{ASSETS_DIR}/"):
            paths.append(relative)
    for name, fragment in out.html.items():
        atomic_write_text(run_dir / "views" / f"{name}.html", _view_page(run_dir, name, fragment))
        paths.append(f"views/{name}.html")
    return WrittenReport(tuple(paths), tuple(out.notes), "; ".join(errors) or None)


# --------------------------------------------------------------------------- the run page


def format_number(value: float, scale: float | None = None) -> str:
    """A float for a reader: four significant digits, plain notation from 0.001 to 1e6, else
    scientific with three; a value below 1e-9 of its column's largest magnitude ``scale`` (rounding
    noise such as ``1.8e-16`` next to values near 1) shows as ``0``."""
    if not math.isfinite(value):
        return str(value)
    if value == 0 or (scale and abs(value) < 1e-9 * scale):
        return "0"
    magnitude = abs(value)
    if 1e-3 <= magnitude < 1e6:
        digits = max(0, 3 - int(math.floor(math.log10(magnitude))))
        text = f"{value:.{digits}f}"
        return text.rstrip("0").rstrip(".") if "." in text else text
    mantissa, exponent = f"{value:.3e}".split("e")
    mantissa = mantissa.rstrip("0").rstrip(".")
    return f"{mantissa}e{int(exponent)}"


def _columns(rows: list[dict[str, Any]]) -> list[str]:
    columns: list[str] = []
    for row in rows:
        columns.extend(c for c in row if c not in columns)
    return columns


def html_table(rows: list[dict[str, Any]], limit: int = 200) -> str:
    """An HTML table of ``rows`` in a box that scrolls sideways, numbers formatted per column."""
    if not rows:
        return "<p><em>empty</em></p>"
    columns = _columns(rows)
    scales = {c: max((abs(r[c]) for r in rows if isinstance(r.get(c), float) and math.isfinite(r[c])), default=0.0)
              for c in columns}

    def fmt(column: str, v: Any) -> str:
        if isinstance(v, bool) or v is None:
            return "" if v is None else str(v)
        if isinstance(v, float):
            return format_number(v, scales[column])
        return html.escape(str(_cell(v)))

    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(
        f"<td class='num'>{fmt(c, r.get(c, ''))}</td>" if isinstance(r.get(c), (int, float)) and not isinstance(r.get(c), bool)
        else f"<td>{fmt(c, r.get(c, ''))}</td>" for c in columns) + "</tr>" for r in rows[:limit])
    more = f"<p>... {len(rows) - limit} more rows in the CSV</p>" if len(rows) > limit else ""
    return f"<div class='scroll'><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>{more}"


def humanise(name: str) -> str:
    """A file or key name as words: ``skeleton_vs_noise`` -> ``Skeleton vs noise``."""
    words = " ".join("3D" if w.lower() == "3d" else w for w in name.replace("_", " ").replace("-", " ").split())
    return words[:1].upper() + words[1:]


def report_heading(call) -> tuple[str, str]:
    """(title, caption) of a report: its ``title`` parameter or its name in words, and the report's doc."""
    title = getattr(call.params, "title", "") or ""
    name = getattr(call.params, "name", "") or getattr(call.params, "folder", "") or call.name
    doc = " ".join((inspect.getdoc(get_report(call.name).func) or "").split("\n\n")[0].split()).replace("``", "")
    return (title or humanise(name)), doc


_STYLE = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1400px;padding:0 1em;color:#222;line-height:1.4}
h1{margin-bottom:.2em} h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:2em}
.kind{color:#888;font-size:.7em;font-weight:normal}
.summary{background:#f6f8fa;border:1px solid #ddd;border-radius:6px;padding:.6em 1em}
.summary dt{font-weight:600;float:left;clear:left;width:9em} .summary dd{margin-left:9.5em}
.scroll{overflow-x:auto;max-width:100%;margin:.5em 0}
table{border-collapse:collapse;font-size:12px} td,th{border:1px solid #ccc;padding:2px 6px;white-space:nowrap}
th{background:#f0f0f0;position:sticky;top:0} td.num{text-align:right;font-variant-numeric:tabular-nums}
figure{margin:1em 0} figure img{max-width:100%;border:1px solid #eee} figcaption{color:#555;font-size:.9em}
.err{color:#b00} .ok{color:#070} nav ul{columns:2}
"""


def _summary(experiment, manifest: dict, written: dict[str, WrittenReport]) -> str:
    esc = html.escape
    n_failed = manifest["n_failed"]
    stages = " &rarr; ".join(esc(c.label) for c in experiment.calls)
    sweep = "; ".join(f"{esc(k)}: {esc(', '.join(map(str, v)))}" for k, v in experiment.raw.sweep.items()) or "none"
    status = (f"<span class='err'>{n_failed} of {manifest['n_items']} items failed</span> (listed below)"
              if n_failed else f"<span class='ok'>all {manifest['n_items']} items ok</span>")
    failed_reports = [label for label, record in written.items() if record.error is not None]
    if failed_reports:  # the items can all be fine while a report of them is not
        status += (f"; <span class='err'>{len(failed_reports)} of {len(written)} reports failed</span> "
                   f"({esc(', '.join(failed_reports))}: the error is in their section)")
    reports = ", ".join(esc(call.name) for call in experiment.reports) or "none"
    return (
        "<dl class='summary'>"
        f"<dt>Status</dt><dd>{status}</dd>"
        f"<dt>Inputs</dt><dd>{len(experiment.inputs)} &times; {len(experiment.sweep_points())} sweep points "
        f"= {manifest['n_items']} items</dd>"
        f"<dt>Sweep</dt><dd>{sweep}</dd><dt>Stages</dt><dd>{stages}</dd><dt>Reports</dt><dd>{reports}</dd>"
        f"<dt>Time</dt><dd>{manifest['seconds']['compute']:.1f} s computing, {manifest['seconds']['total']:.1f} s "
        f"in all; started {esc(manifest['started'])}; cache hits {manifest['cache']['hits']} of "
        f"{manifest['cache']['stage_results']} stage results</dd>"
        f"<dt>Files</dt><dd><a href='config.yaml'>config.yaml</a> (hash <code>{esc(manifest['config_hash'])}</code>) "
        f"&middot; <a href='manifest.json'>manifest.json</a> &middot; <a href='tables/results.csv'>results.csv</a></dd>"
        "</dl>")


def _figure_paths(paths: list[str]) -> dict[str, list[str]]:
    """Figure stem -> its files in every format, in order."""
    out: dict[str, list[str]] = {}
    for p in paths:
        if p.startswith("figures/"):
            out.setdefault(str(Path(p).with_suffix("")), []).append(p)
    return out


def _section(run_dir: Path, label: str, call, record: WrittenReport, number: int, figures: list[int]) -> str:
    """One report's section; ``figures`` holds the running figure count (updated)."""
    esc = html.escape
    title, caption = report_heading(call) if call is not None else (humanise(label), "")
    parts = [f"<h2 id='r{number}'>{esc(title)} <span class='kind'>({esc(label)})</span></h2>"]
    if caption:
        parts.append(f"<p>{esc(caption)}</p>")
    if record.error is not None:
        parts.append(f"<p class='err'>Error: {esc(record.error)}</p>")
    parts += [f"<p>{esc(note)}</p>" for note in record.notes]
    paths = record.files
    for stem, files in _figure_paths(paths).items():
        figures[0] += 1
        shown = next((f for f in files if f.endswith((".png", ".svg"))), None)
        links = " &middot; ".join(f"<a href='{esc(f)}'>{esc(Path(f).suffix[1:].upper())}</a>" for f in files)
        name = humanise(Path(stem).name)
        image = f"<img src='{esc(shown)}' alt='{esc(name)}'>" if shown else ""
        parts.append(f"<figure>{image}<figcaption>Figure {figures[0]}: {esc(name)}. {esc(caption)} "
                     f"Files: {links}</figcaption></figure>")
    for p in paths:
        if p.startswith("views/"):
            page = (run_dir / p).read_text()
            parts.append(page[page.index("<!--view-->") + 11:page.index("<!--/view-->")]
                         + f"<p class='kind'><a href='{esc(p)}'>open this view on its own page</a></p>")
        elif p.endswith(".csv"):
            rows = json.loads((run_dir / p.replace(".csv", ".json")).read_text())
            parts.append(f"<h3>Table: {esc(humanise(Path(p).stem))} <span class='kind'>(<a href='{esc(p)}'>CSV</a>, "
                         f"{len(rows)} rows)</span></h3>" + html_table(rows))
    others = [p for p in paths if not p.startswith(("figures/", "views/", "tables/"))]
    if others:
        parts.append(f"<details><summary>{len(others)} files written</summary><ul>"
                     + "".join(f"<li><a href='{esc(p)}'>{esc(p)}</a></li>" for p in others) + "</ul></details>")
    return "\n".join(parts)


def write_index_html(run_dir: Path, experiment, results, manifest: dict, written: dict[str, WrittenReport]) -> None:
    """A single page with the run's summary, then each report's figures, views and tables, then all items."""
    esc = html.escape
    calls = dict(report_labels(experiment))
    scripts = sorted(p.relative_to(run_dir).as_posix() for p in (run_dir / ASSETS_DIR).glob("*.js")) \
        if (run_dir / ASSETS_DIR).is_dir() else []
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{esc(experiment.name)}</title><style>{_STYLE}</style>{_ERROR_HOOK}",
        *(f"<script src='{esc(s)}'></script>" for s in scripts),
        "</head><body>",
        f"<h1>{esc(experiment.name)}</h1><p>{esc(experiment.raw.description)}</p>",
        _summary(experiment, manifest, written),
    ]
    failed = [r for r in results if not r.ok]
    if failed:
        parts.append("<h2>Failed items</h2><ul>" + "".join(f"<li class='err'>{esc(r.error or '')}</li>" for r in failed) + "</ul>")
    sections = list(written.items())
    if len(sections) > 1:
        parts.append("<nav><h2>Contents</h2><ul>" + "".join(
            f"<li><a href='#r{i}'>{esc(report_heading(calls[label])[0] if label in calls else humanise(label))}</a></li>"
            for i, (label, _) in enumerate(sections, 1)) + "<li><a href='#items'>All items</a></li></ul></nav>")
    figures = [0]
    for i, (label, record) in enumerate(sections, 1):
        parts.append(_section(run_dir, label, calls.get(label), record, i, figures))
    parts.append("<h2 id='items'>All items</h2><p>One row per input and sweep point: the summary of every stage "
                 "(<a href='tables/results.csv'>CSV</a>).</p>" + html_table([r.row() for r in results]))
    parts.append("</body></html>")
    atomic_write_text(run_dir / "index.html", "\n".join(parts))
