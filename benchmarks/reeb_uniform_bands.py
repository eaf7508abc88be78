"""The Reeb graph's cycle count on the bundled double torus with the thesis's uniform bands alone and with the band
splitting that topomatch adds (``reeb_graph(split_handle_bands=True)``, the default: a band whose piece holds a handle
is halved until none does), for several numbers of bands R, clean and with 0.4 % vertex noise.

With the splitting, cycles = genus on a closed surface by construction (docs/skeletons.md), so the thesis page reports
that count without counting it as evidence (Figs. 3.2, 3.3, 3.9, 3.10, 4.9; ``topomatch.thesis``); this script shows
what the count is without it. Run::

    .venv/bin/python benchmarks/reeb_uniform_bands.py [--json benchmarks/results/reeb_uniform_bands.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from topomatch.pipeline.paths import BUNDLED_DIR
from topomatch.stages.mesh.io import read_mesh
from topomatch.stages.morse.mixture import mixture_distance
from topomatch.stages.reeb.level_sets import level_values
from topomatch.stages.reeb.reeb_graph import reeb_graph

BANDS = (8, 12, 16, 22, 28)
NOISE = 0.004
"""Gaussian vertex noise, as a fraction of the bounding-box diagonal (the robustness/noise config's largest)."""


def counts(V: np.ndarray, F: np.ndarray, bands: int) -> dict:
    f = mixture_distance(V, F).values
    uniform = reeb_graph(V, F, f, level_values(f, bands), split_handle_bands=False)
    split = reeb_graph(V, F, f, level_values(f, bands))
    return {"bands": bands, "uniform_cycles": int(uniform.cycle_rank), "split_cycles": int(split.cycle_rank),
            "split_levels_used": len(split.levels) - 1}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    mesh, _ = read_mesh(BUNDLED_DIR / "meshes" / "eight_genus2.off")
    rows = [{"mesh": "clean", **counts(mesh.V, mesh.F, r)} for r in BANDS]
    rng = np.random.default_rng(11)
    noisy = mesh.V + rng.normal(size=mesh.V.shape) * NOISE * np.linalg.norm(np.ptp(mesh.V, axis=0))
    rows.append({"mesh": f"noise {NOISE:g}", **counts(noisy, mesh.F, 22)})
    for r in rows:
        print(f"{r['mesh']:12s} R = {r['bands']:2d}: uniform bands {r['uniform_cycles']} cycles; with splitting "
              f"{r['split_cycles']} ({r['split_levels_used']} levels used); genus 2")
    if args.json:
        args.json.write_text(json.dumps({"about": __doc__.splitlines()[0], "genus": 2, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
