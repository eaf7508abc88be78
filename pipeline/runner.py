"""Running an experiment: items -> executor -> cached stage results -> run folder.

A run writes ``<out>/<config name>-<content hash>/``::

    config.yaml      the resolved config (all defaults filled in)
    manifest.json    versions, seeds, timings, cache hits, errors per item
    tables/          results.csv/.json (one row per item) and report tables
    figures/         PNG figures of the reports
    index.html       a page that shows all of it
    INCOMPLETE       only while the run has not finished (or when it was killed): resume by running again

Stage results are cached by content hash (see :mod:`topomatch.pipeline.cache`), so an
interrupted run resumes where it stopped and a changed parameter recomputes
only the stages downstream of it.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import yaml
from topomatch.pipeline.experiment import Experiment
from topomatch.pipeline.executors import execute
from topomatch.pipeline.files import atomic_write_text
from topomatch.pipeline.item import ItemResult
from topomatch.pipeline.manifest import build_manifest
from topomatch.pipeline.reports import (
    run_reports,
    write_index_html,
    WrittenReport,
    write_table,
)
from tqdm import tqdm

DEFAULT_OUT = Path("runs")
CACHE_DIRNAME = ".cache"
#: A run folder holding this file is incomplete (running, killed or interrupted).
INCOMPLETE = "INCOMPLETE"


def _previous_reports(run_dir: Path) -> dict[str, tuple[str, WrittenReport]]:
    """{report label: (key, what it wrote)} from the run folder's last complete manifest, if any (an
    unreadable manifest: nothing to reuse; one of an earlier release is read too)."""
    try:
        manifest = json.loads((run_dir / "manifest.json").read_text())
        keys, outputs = manifest.get("report_keys", {}), manifest.get("outputs", {})
        return {label: (key, WrittenReport.from_json(outputs[label])) for label, key in keys.items() if label in outputs}
    except (OSError, ValueError, AttributeError, TypeError, KeyError):
        return {}


@dataclass
class RunOutcome:
    """Where a run wrote its results, and what each item produced."""

    run_dir: Path
    items: list[ItemResult]
    manifest: dict[str, Any]

    @property
    def failed(self) -> list[ItemResult]:
        return [r for r in self.items if not r.ok]


def run_experiment(
    experiment: Experiment,
    *,
    out_root: str | Path = DEFAULT_OUT,
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
    progress: bool = True,
) -> RunOutcome:
    """Run every item of ``experiment`` and write its run folder.

    Parameters
    ----------
    out_root : path
        Parent of the run folder.
    cache_dir : path, optional
        Stage cache; default ``<out_root>/.cache``.
    use_cache : bool
        False computes everything and stores nothing.
    progress : bool
        Show a progress bar on stderr.
    """
    out_root = Path(out_root)
    cache_root = None
    if use_cache:  # made first: an unusable cache folder stops the run before anything is written
        cache_root = str(Path(cache_dir) if cache_dir is not None else out_root / CACHE_DIRNAME)
        Path(cache_root).mkdir(parents=True, exist_ok=True)
    run_dir = out_root / f"{experiment.name}-{experiment.content_hash()}"
    run_dir.mkdir(parents=True, exist_ok=True)
    marker = run_dir / INCOMPLETE
    atomic_write_text(marker, f"This run started at {datetime.now(timezone.utc).isoformat(timespec='seconds')} "
                              f"(process {os.getpid()}) and has not finished: it is running, or it was killed or "
                              "interrupted. Its finished stages are cached: run the same command again to resume; "
                              "this file is removed when the run completes.\n")
    atomic_write_text(run_dir / "config.yaml", yaml.safe_dump(experiment.resolved(), sort_keys=False))

    items = experiment.items()
    started = datetime.now(timezone.utc)
    t0 = time.perf_counter()
    by_id: dict[str, ItemResult] = {}
    with tqdm(total=len(items), desc=experiment.name, unit="item", disable=not progress, leave=False) as bar:
        for result in execute(items, cache_root, experiment.raw.executor):
            by_id[result.item_id] = result
            bar.set_postfix_str(result.item_id[-40:])
            bar.update()
    results = [by_id[item.item_id] for item in items]
    compute_seconds = time.perf_counter() - t0

    write_table(run_dir / "tables", "results", [r.row() for r in results])
    written, reused, report_keys = run_reports(experiment, results, run_dir, reuse=_previous_reports(run_dir),
                                               figure_format=experiment.raw.figure_format, dpi=experiment.raw.dpi)
    manifest = build_manifest(
        experiment, results, started=started, compute_seconds=compute_seconds,
        total_seconds=time.perf_counter() - t0, cache_root=cache_root,
        outputs={label: record.to_json() for label, record in written.items()},
    )
    manifest["report_keys"] = report_keys
    manifest["reports_reused"] = sorted(reused)
    atomic_write_text(run_dir / "manifest.json", json.dumps(manifest, indent=2, default=str))
    write_index_html(run_dir, experiment, results, manifest, written)
    marker.unlink(missing_ok=True)
    return RunOutcome(run_dir, results, manifest)
