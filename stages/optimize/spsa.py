"""Simultaneous perturbation stochastic approximation (Spall), maximising, with the usual "modifications".

Plain SPSA (Spall 1992, 1998), written for maximisation of ``L(theta)``::

    g_k = [L(theta_k + c_k D_k) - L(theta_k - c_k D_k)] / (2 c_k D_k)     (element-wise)
    theta_{k+1} = theta_k + a_k g_k
    a_k = a / (A + k + 1) ** 0.602,   c_k = c / (k + 1) ** 0.101

with ``D_k`` a vector of independent +-1 (Bernoulli) entries: two evaluations of L per
iteration whatever the number of parameters. The modifications (all optional, see
:class:`SPSASettings`):

- **parameter scaling**: the optimiser works on ``z = theta / scales``, so one unit of every
  parameter moves the image by about the same amount (the registration uses 1 px for the
  translations and the angle that moves pixels by 1 px RMS);
- **gain calibration**: if ``a`` is not given, it is set so that the first step has length
  ``step`` (Spall's recommendation), from the mean magnitude of ``calibration`` gradient
  estimates at the start; this makes the gains independent of the scale of the measure (JT, MI
  and JR differ by orders of magnitude). With ``newton > 0`` the same evaluations also give the
  curvature ``lambda`` of the objective along the perturbations (second differences), and the
  first gain is at most ``newton / lambda`` (a fraction of a Newton step), which keeps the
  iteration stable and fast near the maximum;
- **gradient averaging**: ``average`` independent gradient estimates per iteration;
- **normalised steps** (``normalize``): the step is ``a_k g / |g|``, so the gains set step
  *lengths* (``a_0 = step``) and only the direction comes from the gradient estimate. The
  entropic measures have sharp peaks with long, flat flanks: the gradient's magnitude says little
  about the distance to the optimum, its direction says a lot. With ``c_step_ratio > 0`` the
  perturbation is also at most ``c_step_ratio * a_k``: a perturbation much longer than the step
  straddles the peak once the iterate is close to it, and the difference quotient loses its sign;
- **step blocking**: a step longer than ``max_step`` is shortened to ``max_step``; with
  ``blocking``, a step is rejected when the objective at the new point falls below the current
  value by more than ``block_tolerance`` times its magnitude (one more evaluation per iteration),
  and the gain ``a`` is multiplied by ``shrink`` (1: plain blocking; < 1 adapts the gain to the
  curvature it meets);
- **bounds**: every evaluated point is projected (clipped) into ``[lower, upper]``;
- **stopping**: after ``iterations``, or when the last ``window`` steps are all shorter than
  ``tol`` (converged), or when the callback returns True;
- **iterate averaging**: the result is the mean of the last ``average_last`` iterates
  (Polyak-Ruppert), which removes the zig-zag of the last steps;
- **continuation**: ``start = m`` continues a gain sequence at iteration m (a_k, c_k with k + m)
  instead of restarting it with the large first steps.

The random perturbations come from the ``numpy.random.Generator`` passed in, so a seed gives
the same run. Invalid points (``L = -inf``, e.g. too little overlap) are handled explicitly: a
gradient estimate with one invalid side steps away from it by the calibrated step length, one
with both sides invalid is skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class SPSASettings:
    """Settings of :func:`spsa_maximize` (lengths in scaled units ``z = theta / scales``)."""

    iterations: int = 100
    a: float | None = None
    A: float | None = None
    c: float = 1.0
    alpha: float = 0.602
    gamma: float = 0.101
    step: float = 1.0
    calibration: int = 4
    average: int = 1
    max_step: float | None = None
    blocking: bool = False
    block_tolerance: float = 0.0
    tol: float = 0.0
    window: int = 10
    average_last: int = 1
    newton: float = 0.0
    shrink: float = 1.0
    normalize: bool = False
    c_step_ratio: float = 0.0
    start: int = 0

    def gain_A(self) -> float:
        """Stability constant A: given, or 10 % of the iterations (Spall)."""
        return self.A if self.A is not None else 0.1 * self.iterations


@dataclass
class OptimizeResult:
    """What an optimiser returns.

    Attributes
    ----------
    theta : ndarray, shape (p,)
        The best parameters found (unscaled).
    value : float
        Objective at ``theta``.
    iterations, evaluations : int
    stop_reason : str
        ``'max_iterations'``, ``'converged'``, ``'callback'``, ``'invalid_start'``, or the
        optimiser's own message (Powell).
    history : dict of ndarray
        Per iteration: ``theta`` (k, p), ``value`` (k,) (the mean of the two perturbed
        evaluations for SPSA, L(theta_k) for Powell), ``step`` (k,) step length in scaled
        units, ``blocked`` (k,) bool.
    """

    theta: np.ndarray
    value: float
    iterations: int
    evaluations: int
    stop_reason: str
    history: dict[str, np.ndarray] = field(default_factory=dict)


def callback_stops(answer) -> bool:
    """Whether an iteration callback's answer stops the optimiser: True (or a non-zero integer) stops, False or None
    goes on; anything else is a TypeError (an array's truth value would be numpy's ambiguity error, deep inside the
    run)."""
    if answer is None or isinstance(answer, (bool, int, np.bool_, np.integer)):
        return bool(answer)
    raise TypeError(f"an iteration callback must return True (stop), False or None, not {type(answer).__name__}")


def spsa_maximize(f: Callable[[np.ndarray], float], theta0, settings: SPSASettings, *, rng: np.random.Generator,
                  scales=None, lower=None, upper=None,
                  callback: Callable[[int, np.ndarray, float], bool | None] | None = None) -> OptimizeResult:
    """Maximise ``f`` from ``theta0`` with SPSA.

    Parameters
    ----------
    f : callable
        ``f(theta) -> float``, ``-inf`` for an invalid point.
    theta0 : array_like, shape (p,)
    settings : SPSASettings
    rng : numpy.random.Generator
        Source of the +-1 perturbations.
    scales : array_like, shape (p,), optional
        Parameter scales (default 1).
    lower, upper : array_like, shape (p,), optional
        Bounds on theta (default none).
    callback : callable, optional
        ``callback(k, theta_k, value_k)`` after each iteration; returning True stops.

    Returns
    -------
    OptimizeResult
    """
    s = settings
    theta0 = np.asarray(theta0, dtype=np.float64)
    p = theta0.size
    scales = np.ones(p) if scales is None else np.asarray(scales, dtype=np.float64)
    lo = np.full(p, -np.inf) if lower is None else np.asarray(lower, dtype=np.float64) / scales
    hi = np.full(p, np.inf) if upper is None else np.asarray(upper, dtype=np.float64) / scales
    n_evals = 0

    def F(z: np.ndarray) -> float:
        nonlocal n_evals
        n_evals += 1
        return float(f(np.minimum(np.maximum(z, lo), hi) * scales))

    signs: list[np.ndarray] = []

    def bernoulli() -> np.ndarray:
        """A vector of independent +-1 entries (probability 1/2 each), drawn in blocks of 256."""
        if not signs:
            signs.extend(rng.integers(0, 2, size=(256, p)) * 2.0 - 1.0)
        return signs.pop()

    z = np.clip(theta0 / scales, lo, hi)
    A = s.gain_A()

    def grad(z: np.ndarray, ck: float) -> tuple[np.ndarray | None, float]:
        """Averaged SPSA gradient estimate and the mean of the evaluations (None if all invalid)."""
        gs, ys = [], []
        for _ in range(max(1, s.average)):
            delta = bernoulli()
            yp, ym = F(z + ck * delta), F(z - ck * delta)
            if math.isfinite(yp) and math.isfinite(ym):
                gs.append((yp - ym) / (2.0 * ck * delta))
                ys.append(0.5 * (yp + ym))
            elif math.isfinite(yp) or math.isfinite(ym):  # step away from the invalid side
                sign = 1.0 if math.isfinite(yp) else -1.0
                gs.append(sign * delta * math.inf)
                ys.append(yp if math.isfinite(yp) else ym)
        if not gs:
            return None, -math.inf
        if len(gs) == 1:
            return gs[0], ys[0]
        with np.errstate(invalid="ignore"):
            g = np.sum(gs, axis=0) / len(gs)
        g[np.isnan(g)] = 0.0  # opposite "away from the invalid side" pushes cancel: no information
        return g, sum(ys) / len(ys)

    # --- gain calibration ----------------------------------------------------------------------
    # First-step gain a0 = a / (A + 1)^alpha. From `calibration` perturbation pairs at the start:
    # the gradient magnitude |g| gives the gain of a first step of length `step`; the second
    # differences (y+ + y- - 2 y0) / c^2 = D^T H D give the curvature lambda along the perturbations,
    # and a0 <= newton / lambda keeps the steps stable near a maximum (a Newton step has a0 = 1/lambda).
    a = s.a
    if a is None and s.normalize:
        a = s.step * (A + 1) ** s.alpha
    elif a is None:
        y0 = F(z)
        mags, curvs = [], []
        for _ in range(max(1, s.calibration)):
            delta = bernoulli()
            yp, ym = F(z + s.c * delta), F(z - s.c * delta)
            if math.isfinite(yp) and math.isfinite(ym):
                mags.append(abs(yp - ym) / (2.0 * s.c))  # |g_i| of the SPSA estimate (same for every i)
                if math.isfinite(y0):
                    curvs.append(-(yp + ym - 2.0 * y0) / (s.c * s.c) / p)
        mag = float(np.mean(mags)) if mags else 0.0
        if mag <= 0:
            reason = "invalid_start" if not math.isfinite(y0) else "flat_objective"
            return OptimizeResult(z * scales, y0, 0, n_evals, reason, _history([], p))
        a0 = s.step / (mag * math.sqrt(p))
        lam = float(np.mean(curvs)) if curvs else 0.0
        if s.newton > 0 and lam > 0:
            a0 = min(a0, s.newton / lam)
        a = a0 * (A + 1) ** s.alpha

    current = F(z) if s.blocking else math.nan
    rows: list[tuple] = []
    recent: list[float] = []
    tail: list[np.ndarray] = []
    stop = "max_iterations"
    k = 0
    for k in range(s.iterations):
        ak = a / (A + k + s.start + 1) ** s.alpha
        ck = s.c / (k + s.start + 1) ** s.gamma
        if s.c_step_ratio > 0 and s.normalize:
            ck = min(ck, s.c_step_ratio * ak)
        g, y = grad(z, ck)
        blocked = False
        if g is None:
            step_vec = np.zeros(p)
            blocked = True
        else:
            if not np.all(np.isfinite(g)):  # one side invalid: a unit-direction step of calibrated length
                g = np.where(np.isposinf(g), 1.0, np.where(np.isneginf(g), -1.0, 0.0))
                step_vec = g / np.linalg.norm(g) * ak * s.step / (a / (A + 1) ** s.alpha)
            elif s.normalize:
                n = math.sqrt(float(g @ g))
                step_vec = ak * g / n if n > 0 else np.zeros(p)
            else:
                step_vec = ak * g
            n = math.sqrt(float(step_vec @ step_vec))
            if s.max_step is not None and n > s.max_step:
                step_vec *= s.max_step / n
        z_new = np.minimum(np.maximum(z + step_vec, lo), hi)
        if s.blocking and not blocked:
            candidate = F(z_new)
            if not math.isfinite(candidate) or candidate < current - s.block_tolerance * abs(current):
                blocked = True
                a *= s.shrink
            else:
                current = candidate
        if blocked:
            z_new = z
        dz = z_new - z
        step_len = math.sqrt(float(dz @ dz))
        z = z_new
        rows.append((z * scales, y, step_len, blocked))
        tail.append(z.copy())
        if len(tail) > max(1, s.average_last):
            tail.pop(0)
        recent.append(step_len)
        if callback is not None and callback_stops(callback(k, z * scales, y)):
            stop = "callback"
            break
        if s.tol > 0 and len(recent) >= s.window and max(recent[-s.window:]) < s.tol:
            stop = "converged"
            break
    z_final = np.mean(tail, axis=0) if tail else z
    z_final = np.clip(z_final, lo, hi)
    value = F(z_final)
    return OptimizeResult(z_final * scales, value, len(rows), n_evals, stop, _history(rows, p))


def _history(rows: list[tuple], p: int) -> dict[str, np.ndarray]:
    if not rows:
        return {"theta": np.zeros((0, p)), "value": np.zeros(0), "step": np.zeros(0), "blocked": np.zeros(0, bool)}
    return {
        "theta": np.array([r[0] for r in rows]),
        "value": np.array([r[1] for r in rows], dtype=np.float64),
        "step": np.array([r[2] for r in rows], dtype=np.float64),
        "blocked": np.array([r[3] for r in rows], dtype=bool),
    }
