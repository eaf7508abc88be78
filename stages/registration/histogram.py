"""Joint intensity histograms of a fixed image and a rigidly transformed moving image, 2D and 3D alike.

:class:`JointHistogram` does once all that does not depend on the transform (its fixed samples, their positions and
bins; the moving image in bin units); an evaluation is then one compiled pass (``_histogram.c``; numpy without it) of
the rigid map, N-linear interpolation and binning. See docs/registration.md, "The joint histogram"."""

from __future__ import annotations

import copy
import os
from dataclasses import dataclass
from typing import Literal

import numpy as np

from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import corners, inside, linear
from topomatch.stages.registration.transform import euler_matrix, n_angles

try:
    from topomatch.stages.registration._histogram import joint_histogram as _compiled
except ImportError:  # pragma: no cover - the extension is built on install; numpy keeps the answers without it
    _compiled = None

Mode = Literal["linear", "parzen", "pv"]
MODES = {"linear": 0, "parzen": 1, "pv": 2}
PARALLEL_SAMPLES = 20000
"""Samples from which the compiled pass splits its work over :func:`histogram_threads` threads (below, a thread's
start costs more than it saves)."""


def histogram_threads() -> int:
    """Threads of the compiled pass: ``$OMP_NUM_THREADS`` when set (the engine's worker processes set it to 1),
    else the CPUs this process may use, at most 4."""
    if (env := os.environ.get("OMP_NUM_THREADS", "")).isdigit() and int(env) > 0:
        return int(env)
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(4, cpus))


@dataclass(frozen=True)
class Binning:
    """Equal-width bins over ``[lo, hi]``: value v goes to ``floor((v - lo) / (hi - lo) * bins)``,
    clipped to ``[0, bins - 1]``."""

    bins: int
    lo: float
    hi: float

    @classmethod
    def of(cls, data: np.ndarray, bins: int) -> "Binning":
        """Bins over the intensity range of ``data``."""
        if bins < 2:
            raise ValueError(f"need at least 2 bins, got {bins}")
        lo, hi = float(np.min(data)), float(np.max(data))
        if not hi > lo:
            raise ValueError("cannot bin a constant image")
        return cls(int(bins), lo, hi)

    @property
    def scale(self) -> float:
        """``bins / (hi - lo)``."""
        return self.bins / (self.hi - self.lo)

    def index(self, values: np.ndarray) -> np.ndarray:
        """Bin of each value (intp, same shape), clipped to ``[0, bins - 1]``."""
        idx = np.floor((np.asarray(values, dtype=np.float64) - self.lo) * self.scale).astype(np.intp)
        return np.clip(idx, 0, self.bins - 1)


class JointHistogram:
    """Joint histograms of ``(fixed(p), moving(T(p)))`` for many rigid transforms ``T(p) = R (p - c) + c + t``.

    The images at this resolution (any pyramid level), binned by ``fixed_binning`` and ``moving_binning`` (usually over
    the full-resolution images' ranges); ``center``: c (d,); the fixed samples: the pixels of ``mask`` (bool, this grid;
    default all), at most ``samples`` of them (a random subset drawn once with ``seed``), each moved by a fixed random
    offset within its pixel with ``jitter``."""

    def __init__(self, fixed: Image, moving: Image, fixed_binning: Binning, moving_binning: Binning, *, center,
                 mode: Mode = "parzen", samples: int | None = None, mask: np.ndarray | None = None,
                 jitter: bool = False, seed: int = 0):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        rng = np.random.default_rng(seed)
        self.dim, self.mode = fixed.dim, mode
        self.center = np.asarray(center, dtype=np.float64)
        self.shape = (fixed_binning.bins, moving_binning.bins)
        self.n_cells = fixed_binning.bins * moving_binning.bins
        flat = np.flatnonzero(mask.ravel()) if mask is not None else np.arange(fixed.data.size)
        if len(flat) == 0:
            raise ValueError("the fixed mask selects no pixel")
        if samples is not None and samples < len(flat):
            flat = np.sort(rng.choice(flat, size=int(samples), replace=False))
        idx = fixed.indices(flat).T  # (d, n)
        if jitter:
            idx += rng.uniform(-0.5, 0.5, size=idx.shape)
            idx = np.clip(idx, 0.0, (np.asarray(fixed.size) - 1.0)[:, None])
            values = linear(fixed.data, idx)[0]
        else:
            values = fixed.data.ravel()[flat]
        self.n_samples = idx.shape[1]
        self._P = np.zeros((3, self.n_samples))  # (3, n): a 2D image is a 3D image of one slice for the compiled pass
        self._P[: self.dim] = (fixed.physical(idx.T) - self.center).T
        self._fbk = np.ascontiguousarray(fixed_binning.index(values) * moving_binning.bins, dtype=np.int64)
        self.moving = moving
        self._inv = np.linalg.inv(moving.index_matrix)
        self._size = tuple(moving.size) + (1,) * (3 - self.dim)
        self._mflat = np.ascontiguousarray((moving.data.ravel() - moving_binning.lo) * moving_binning.scale - 0.5)
        self._mbins = (moving_binning.index(moving.data).ravel() if mode == "pv" else np.zeros(1)).astype(np.int64)
        self._bmax = moving_binning.bins - 1
        self.threads = histogram_threads() if self.n_samples >= PARALLEL_SAMPLES else 1

    def shuffled(self, seed: int = 0) -> "JointHistogram":
        """The same samples with their fixed intensities paired with other samples' (a fixed-seed permutation):
        the histograms of two images that share no structure, with these marginals and this sample count."""
        other = copy.copy(self)
        other._fbk = np.random.default_rng(seed).permutation(self._fbk)
        return other

    def index_map(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """``A`` (3, 3) and ``b`` (3,): moving continuous index ``A p + b`` of a sample at ``p`` (about c)
        (rows and columns beyond the dimension are zero)."""
        theta = np.asarray(theta, dtype=np.float64)
        d, k = self.dim, n_angles(self.dim)
        A, b = np.zeros((3, 3)), np.zeros(3)
        A[:d, :d] = self._inv @ euler_matrix(theta[:k])
        b[:d] = self._inv @ (self.center + theta[k:] - np.asarray(self.moving.origin))
        return A, b

    def positions(self, theta) -> np.ndarray:
        """Continuous moving indices (d, n), ITK order, of the samples under ``theta``."""
        A, b = self.index_map(theta)
        return (A @ self._P + b[:, None])[: self.dim]

    def overlap(self, theta) -> float:
        """Fraction of the samples whose ``T(p)`` lies inside the moving grid."""
        return float(np.mean(inside(self.positions(theta), self._size[: self.dim])))

    def __call__(self, theta) -> tuple[np.ndarray, int]:
        """Joint histogram (fixed bins, moving bins) for ``theta`` and the number of samples inside the moving grid."""
        if _compiled is None:
            return self.histogram_numpy(theta)
        A, b = self.index_map(theta)
        h0, h1 = np.zeros(self.n_cells + 1), np.zeros(self.n_cells + 1)
        n_inside = _compiled(A, b, self._P, self._mflat, self._mbins, self._size, self._fbk, self._bmax,
                             MODES[self.mode], h0, h1, self.threads)
        return (h0[: self.n_cells] + h1[: self.n_cells]).reshape(self.shape), int(n_inside)

    def histogram_numpy(self, theta) -> tuple[np.ndarray, int]:
        """:meth:`__call__` in numpy (2^d corners): the reference of the compiled pass, and its fallback."""
        U = self.positions(theta)
        keep = inside(U, self._size[: self.dim])
        neighbours = corners(U[:, keep], self._size[: self.dim])
        fbk = self._fbk[keep]
        K = self.n_cells
        if self.mode == "pv":
            h = sum(np.bincount(fbk + self._mbins[c], weights=w, minlength=K) for w, c in neighbours)
        else:
            val = sum(w * self._mflat[c] for w, c in neighbours)
            if self.mode == "linear":
                h = np.bincount(fbk + np.clip(np.floor(val + 0.5).astype(np.intp), 0, self._bmax), minlength=K)
            else:
                val = np.clip(val, 0.0, self._bmax)
                m0 = np.minimum(val.astype(np.intp), max(self._bmax - 1, 0))
                h = np.bincount(fbk + m0, weights=1.0 - (val - m0), minlength=K + 1)[:K]
                h = h + np.bincount(fbk + m0 + 1, weights=val - m0, minlength=K + 1)[:K]
        return np.asarray(h, dtype=np.float64).reshape(self.shape), int(np.count_nonzero(keep))


def compiled() -> bool:
    """Whether the compiled pass is installed (else every histogram is computed in numpy)."""
    return _compiled is not None

