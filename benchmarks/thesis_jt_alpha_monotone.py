"""Does the Jensen-Tsallis divergence of a joint histogram fall as alpha rises, whatever the histogram? If so, the
thesis's sentence under Figs. 2.9 and 2.11 ("the maximum falls as alpha rises") holds by construction and is no
evidence about images, and the thesis page (``topomatch.thesis._landscape``) reports it without counting it.

Random 32 x 32 joint histograms of four kinds (powers of uniforms, Dirichlet draws, near-diagonal ones as an
aligned pair gives, sparse ones), both Jensen weightings, alpha = 0.5, 1, 2, 3 (the thesis's values); a histogram
counts as an exception when its divergence does not strictly fall along them. Run::

    .venv/bin/python benchmarks/thesis_jt_alpha_monotone.py [--trials 20000] [--json benchmarks/results/thesis_jt_alpha_monotone.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from topomatch.stages.registration.divergence import jensen_tsallis_histogram

ALPHAS = (0.5, 1.0, 2.0, 3.0)


def random_histogram(rng: np.random.Generator, kind: int, n: int = 32) -> np.ndarray:
    """One (n, n) non-negative histogram of ``kind`` 0-3 (see the module docstring)."""
    if kind == 0:
        return rng.random((n, n)) ** rng.uniform(1, 30)
    if kind == 1:
        return rng.dirichlet(np.full(n * n, rng.uniform(0.01, 1))).reshape(n, n)
    if kind == 2:
        return np.eye(n) * rng.random(n) * rng.uniform(1, 100) + rng.random((n, n)) * rng.uniform(0, 1) ** 3
    return (rng.random((n, n)) < rng.uniform(0.02, 0.3)) * rng.random((n, n))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=20000, help="histograms per weighting")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    out = {}
    for weights in ("histogram", "uniform"):
        rng = np.random.default_rng(0)
        total, exceptions = 0, []
        for trial in range(args.trials):
            h = random_histogram(rng, trial % 4)
            if h.sum() == 0:
                continue
            values = [jensen_tsallis_histogram(h, a, weights=weights) for a in ALPHAS]
            total += 1
            if not all(b < a for a, b in zip(values, values[1:])):
                exceptions.append({"trial": trial, "kind": trial % 4, "values": values})
        out[weights] = {"histograms": total, "exceptions": len(exceptions), "first": exceptions[:5]}
        print(f"{weights} weights: JT not falling with alpha on {len(exceptions)} of {total} random histograms")
    if args.json:
        args.json.write_text(json.dumps({"about": __doc__.splitlines()[0], "alphas": ALPHAS, "results": out}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
