"""Entropies and the entropic similarity measures of thesis ch. 2, computed from a joint histogram.

Rows of ``h`` (n, k) belong to the reference (fixed) image X, columns to the moving Y; the conditional distributions are
the normalised rows ``p_i``. Natural logarithms, ``0 log 0 = 0``, ``0 ** alpha = 0``; Tsallis ``H_a(p) = (sum p^a - 1) /
(1 - a)`` and Renyi ``R_a(p) = log(sum p^a) / (1 - a)`` are exactly Shannon's at a = 1. Measures (maximised at
alignment): Jensen-Tsallis ``JT = H_a(sum w_i p_i) - sum w_i H_a(p_i)``, Jensen-Renyi (the same with R_a), mutual
information, Tsallis MI (``form='additive'``: ``S(X) + S(Y) + (1 - a) S(X) S(Y) - S(X, Y)``, Martin et al. 2004;
``'relative'``: the Tsallis relative entropy of the joint to the product of the marginals). Weights: ``'histogram'``
(the thesis's: the fixed marginal) or ``'uniform'`` over the non-empty rows; empty rows are left out. See
docs/registration.md, "Measures"."""

from __future__ import annotations

from typing import Literal

import numpy as np

Metric = Literal["jt", "jr", "mi", "tmi"]
Weights = Literal["histogram", "uniform"]
METRIC_NAMES = {"jt": "Jensen-Tsallis", "jr": "Jensen-Renyi", "mi": "mutual information", "tmi": "Tsallis MI"}

_ONE = 1e-9  # |alpha - 1| below this uses the Shannon formula


def _check_alpha(alpha: float) -> None:
    if not alpha > 0:
        raise ValueError(f"alpha must be > 0, got {alpha}")


def _power_sum(p: np.ndarray, alpha: float, axis: int = -1) -> np.ndarray:
    """``sum p^alpha`` along ``axis`` with ``0^alpha = 0``."""
    if alpha == 2.0:
        return np.einsum("...i,...i->...", p, p) if axis in (-1, p.ndim - 1) else (p * p).sum(axis=axis)
    return np.where(p > 0, np.power(np.where(p > 0, p, 1.0), alpha), 0.0).sum(axis=axis)


def shannon_entropy(p: np.ndarray, axis: int = -1) -> np.ndarray:
    """``-sum p log p`` along ``axis`` (natural log, ``0 log 0 = 0``). p: any shape of probabilities."""
    p = np.asarray(p, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return -np.where(p > 0, p * np.log(np.where(p > 0, p, 1.0)), 0.0).sum(axis=axis)


def _of_order(p: np.ndarray, alpha: float, axis: int, of_power_sum) -> np.ndarray:
    """``of_power_sum(sum p^alpha)`` along ``axis``; Shannon's entropy at ``alpha = 1``."""
    _check_alpha(alpha)
    p = np.asarray(p, dtype=np.float64)
    return shannon_entropy(p, axis) if abs(alpha - 1.0) < _ONE else of_power_sum(_power_sum(p, alpha, axis))


def tsallis_entropy(p: np.ndarray, alpha: float, axis: int = -1) -> np.ndarray:
    """Tsallis entropy ``(sum p^a - 1) / (1 - a)`` along ``axis``; Shannon at ``a = 1``."""
    return _of_order(p, alpha, axis, lambda s: (s - 1.0) / (1.0 - alpha))


def renyi_entropy(p: np.ndarray, alpha: float, axis: int = -1) -> np.ndarray:
    """Renyi entropy ``log(sum p^a) / (1 - a)`` along ``axis``; Shannon at ``a = 1``."""
    with np.errstate(divide="ignore"):
        return _of_order(p, alpha, axis, lambda s: np.log(s) / (1.0 - alpha))


def _jensen(entropy, P: np.ndarray, weights: np.ndarray, alpha: float) -> float:
    P = np.asarray(P, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    if P.ndim != 2 or w.shape != (P.shape[0],):
        raise ValueError(f"expected distributions (n, k) and weights (n,), got {P.shape} and {w.shape}")
    if np.any(w < 0) or not np.isclose(w.sum(), 1.0):
        raise ValueError(f"weights must be >= 0 and sum to 1 (sum {w.sum():.6g})")
    return float(entropy(w @ P, alpha) - w @ entropy(P, alpha, axis=1))


def jensen_tsallis(P: np.ndarray, weights: np.ndarray, alpha: float) -> float:
    """``H_a(sum w_i p_i) - sum w_i H_a(p_i)`` for distributions ``P`` (n, k) and weights (n,)."""
    return _jensen(tsallis_entropy, P, weights, alpha)


def jensen_renyi(P: np.ndarray, weights: np.ndarray, alpha: float) -> float:
    """``R_a(sum w_i p_i) - sum w_i R_a(p_i)`` for distributions ``P`` (n, k) and weights (n,)."""
    return _jensen(renyi_entropy, P, weights, alpha)


def conditionals(h: np.ndarray, weights: Weights = "histogram") -> tuple[np.ndarray, np.ndarray]:
    """Conditional distributions of a joint histogram ``h`` (n, k; counts or probabilities, rows = reference bins):
    its rows with a positive sum, each normalised to sum 1, ``P`` (n', k), and their weights ``w`` (n',; sum 1);
    both empty if ``h`` has no mass."""
    h = np.asarray(h, dtype=np.float64)
    rows = h.sum(axis=1)
    keep = rows > 0
    P = h[keep] / rows[keep, None]
    if weights == "histogram":
        w = rows[keep] / rows.sum() if keep.any() else rows[keep]
    elif weights == "uniform":
        w = np.full(int(keep.sum()), 1.0 / max(int(keep.sum()), 1))
    else:
        raise ValueError(f"weights must be 'histogram' or 'uniform', got {weights!r}")
    return P, w


def jensen_tsallis_histogram(h: np.ndarray, alpha: float = 2.0, weights: Weights = "histogram") -> float:
    """Jensen-Tsallis divergence of the conditional distributions of a joint histogram (n, k)."""
    _check_alpha(alpha)
    h = np.asarray(h, dtype=np.float64)
    rows = h.sum(axis=1)
    keep = rows > 0
    if not keep.any():
        return float("nan")
    if alpha == 2.0 and weights == "histogram":  # the thesis's closed form, sum h_ij^2/(N h_i.) - sum (h_.j/N)^2
        N = rows.sum()
        cols = h.sum(axis=0)
        q = np.einsum("ij,ij->i", h, h)
        return float((q[keep] / rows[keep]).sum() / N - (cols @ cols) / (N * N))
    hk, rk = h[keep], rows[keep]
    P = hk / rk[:, None]
    if weights == "histogram":
        w = rk / rk.sum()
        mixture = hk.sum(axis=0) / rk.sum()
    else:
        w = np.full(len(rk), 1.0 / len(rk))
        mixture = P.mean(axis=0)
    return float(tsallis_entropy(mixture, alpha) - w @ tsallis_entropy(P, alpha, axis=1))


def jensen_renyi_histogram(h: np.ndarray, alpha: float = 2.0, weights: Weights = "histogram") -> float:
    """Jensen-Renyi divergence of the conditional distributions of a joint histogram (n, k)."""
    P, w = conditionals(h, weights)
    return jensen_renyi(P, w, alpha) if len(w) else float("nan")


def mutual_information(h: np.ndarray) -> float:
    """``H(X) + H(Y) - H(X, Y)`` of a joint histogram (n, k) (natural log)."""
    h = np.asarray(h, dtype=np.float64)
    if (total := h.sum()) <= 0:
        return float("nan")
    p = h / total
    return float(shannon_entropy(p.sum(axis=1)) + shannon_entropy(p.sum(axis=0)) - shannon_entropy(p.ravel()))


def tsallis_mutual_information(h: np.ndarray, alpha: float = 2.0, form: Literal["additive", "relative"] = "additive") -> float:
    """Tsallis mutual information of a joint histogram (n, k); see the module docstring for the forms."""
    _check_alpha(alpha)
    h = np.asarray(h, dtype=np.float64)
    if (total := h.sum()) <= 0:
        return float("nan")
    if abs(alpha - 1.0) < _ONE:
        return mutual_information(h)
    p = h / total
    px, py = p.sum(axis=1), p.sum(axis=0)
    if form == "additive":
        sx, sy = tsallis_entropy(px, alpha), tsallis_entropy(py, alpha)
        return float(sx + sy + (1.0 - alpha) * sx * sy - tsallis_entropy(p.ravel(), alpha))
    if form == "relative":
        nz = p > 0
        q = np.outer(px, py)[nz]
        s = np.sum(p[nz] ** alpha * q ** (1.0 - alpha))
        return float((s - 1.0) / (alpha - 1.0))
    raise ValueError(f"form must be 'additive' or 'relative', got {form!r}")


def similarity(h: np.ndarray, metric: Metric, *, alpha: float = 2.0, weights: Weights = "histogram",
               tmi_form: Literal["additive", "relative"] = "additive") -> float:
    """The measure ``metric`` ('jt', 'jr', 'mi', 'tmi') of a joint histogram; NaN if it is empty."""
    if metric == "jt":
        return jensen_tsallis_histogram(h, alpha, weights)
    if metric == "jr":
        return jensen_renyi_histogram(h, alpha, weights)
    if metric == "mi":
        return mutual_information(h)
    if metric == "tmi":
        return tsallis_mutual_information(h, alpha, tmi_form)
    raise ValueError(f"unknown metric {metric!r}; expected one of {', '.join(METRIC_NAMES)}")
