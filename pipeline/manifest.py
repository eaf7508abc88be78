"""The run manifest: what ran, with which versions, seeds, timings and cache hits."""

from __future__ import annotations

import platform
import sys
from datetime import datetime, timezone
from importlib import metadata
from typing import Any

from topomatch.pipeline.experiment import Experiment
from topomatch.pipeline.item import ItemResult

#: Distributions whose versions are recorded in every manifest.
RECORDED_PACKAGES = (
    "topomatch", "numpy", "scipy", "libigl", "pymeshlab", "fast-simplification", "open3d",
    "networkx", "pyyaml", "pydantic", "matplotlib", "dask", "distributed",
)


def package_versions(names: tuple[str, ...] = RECORDED_PACKAGES) -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def seeds(experiment: Experiment) -> dict[str, Any]:
    """Every parameter whose name contains 'seed', as ``label.param``, plus swept seeds."""
    found = {}
    for call in experiment.calls:
        for name, value in call.params.canonical().items():
            if "seed" in name:
                found[f"{call.label}.{name}"] = value
    for key, values in experiment.raw.sweep.items():
        if "seed" in key.split(".")[-1]:
            found[key] = values
    return found


def build_manifest(
    experiment: Experiment,
    results: list[ItemResult],
    *,
    started: datetime,
    compute_seconds: float,
    total_seconds: float,
    cache_root: str | None,
    outputs: dict[str, dict[str, Any]],
) -> dict[str, Any]:
    hits = sum(sum(r.cache_hits.values()) for r in results)
    runs = sum(len(r.cache_hits) for r in results)
    return {
        "name": experiment.name,
        "config": str(experiment.source) if experiment.source else None,
        "config_hash": experiment.content_hash(),
        "started": started.isoformat(timespec="seconds"),
        "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "seconds": {"compute": round(compute_seconds, 4), "total": round(total_seconds, 4)},
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "packages": package_versions(),
        "executor": experiment.raw.executor.model_dump(mode="json"),
        "cache": {"dir": cache_root, "stage_results": runs, "hits": hits},
        "seeds": seeds(experiment),
        "stage_versions": {c.label: c.spec.version for c in experiment.calls},
        "n_items": len(results),
        "n_failed": sum(not r.ok for r in results),
        "outputs": outputs,
        "items": [
            {
                "item": r.item_id,
                "input": r.input_path,
                "sweep": r.sweep,
                "status": "ok" if r.ok else "failed",
                "error": r.error,
                "error_stage": r.error_stage,
                "traceback": r.traceback,
                "seconds": {k: round(v, 6) for k, v in r.seconds.items()},
                "cache_hits": r.cache_hits,
                "cache_keys": r.keys,
            }
            for r in results
        ],
    }
