"""A deterministic optimiser for the same objectives: Powell's conjugate-direction method (scipy).

Same interface as :func:`topomatch.stages.optimize.spsa.spsa_maximize`: it maximises ``f`` over
parameters scaled by ``scales``, within bounds, and returns an
:class:`~topomatch.stages.optimize.spsa.OptimizeResult` with a per-iteration history. Invalid points
(``f = -inf``) become a large finite penalty for scipy's line searches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from topomatch.stages.optimize.spsa import OptimizeResult, callback_stops


@dataclass(frozen=True)
class PowellSettings:
    """Settings of :func:`powell_maximize` (lengths in scaled units)."""

    max_evaluations: int = 400
    xtol: float = 0.01
    ftol: float = 1e-6
    step: float = 1.0  # length of the initial search directions


def powell_maximize(f: Callable[[np.ndarray], float], theta0, settings: PowellSettings, *, scales=None,
                    lower=None, upper=None,
                    callback: Callable[[int, np.ndarray, float], bool | None] | None = None) -> OptimizeResult:
    """Maximise ``f`` from ``theta0`` with scipy's Powell method (deterministic).

    Parameters
    ----------
    f : callable
        ``f(theta) -> float``; ``-inf`` marks an invalid point.
    theta0 : array_like, shape (p,)
    settings : PowellSettings
    scales, lower, upper : array_like, shape (p,), optional
        As for SPSA.
    callback : callable, optional
        ``callback(k, theta_k, value_k)`` after each Powell iteration; True stops.
    """
    from scipy.optimize import minimize

    theta0 = np.asarray(theta0, dtype=np.float64)
    p = theta0.size
    scales = np.ones(p) if scales is None else np.asarray(scales, dtype=np.float64)
    bounds = None
    z0 = theta0 / scales
    if lower is not None or upper is not None:
        lo = np.full(p, -np.inf) if lower is None else np.asarray(lower, float) / scales
        hi = np.full(p, np.inf) if upper is None else np.asarray(upper, float) / scales
        bounds = list(zip(lo, hi))
        z0 = np.minimum(np.maximum(z0, lo), hi)
    n_evals = 0
    cache: dict[bytes, float] = {}

    def neg(z: np.ndarray) -> float:
        nonlocal n_evals
        key = np.asarray(z, dtype=np.float64).tobytes()
        if key not in cache:
            n_evals += 1
            v = float(f(np.asarray(z) * scales))
            cache[key] = -v if math.isfinite(v) else 1e30
        return cache[key]

    rows: list[tuple] = []
    last = [z0]
    stopped = [False]

    def cb(zk: np.ndarray) -> bool:
        value = -neg(zk)
        rows.append((zk * scales, value, float(np.linalg.norm(zk - last[0])), False))
        last[0] = zk.copy()
        if callback is not None and callback_stops(callback(len(rows) - 1, zk * scales, value)):
            stopped[0] = True
            return True
        return False

    res = minimize(neg, z0, method="Powell", bounds=bounds, callback=cb,
                   options={"xtol": settings.xtol, "ftol": settings.ftol, "maxfev": settings.max_evaluations,
                            "direc": np.eye(p) * settings.step})
    theta = np.asarray(res.x, dtype=np.float64) * scales
    value = -neg(res.x)
    reason = "callback" if stopped[0] else ("converged" if res.success else str(res.message))
    history = {
        "theta": np.array([r[0] for r in rows]).reshape(-1, p),
        "value": np.array([r[1] for r in rows], dtype=np.float64),
        "step": np.array([r[2] for r in rows], dtype=np.float64),
        "blocked": np.zeros(len(rows), dtype=bool),
    }
    return OptimizeResult(theta, value if value > -1e29 else -math.inf, len(rows), n_evals, reason, history)
