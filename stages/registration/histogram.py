"""Joint intensity histograms of a fixed image and a transformed moving image, fast.

The expensive part of every objective evaluation is the joint histogram of
``(fixed(x), moving(T(x)))`` over the fixed pixels x. :class:`JointHistogram` does all that
does not depend on ``T`` once: the fixed pixels' bins (already multiplied by the number of
moving bins), their positions relative to the rotation centre in moving-pixel units, and for
partial-volume interpolation the binned moving image. One evaluation is then ~20 vectorised
numpy operations on the sample arrays and one ``np.bincount`` on the combined index
``fixed_bin * moving_bins + moving_bin`` (samples outside the moving image go to an extra
cell that is dropped).

Binning: ``bins`` equal-width bins over each image's own intensity range ``[min, max]``
(the top value falls in the last bin), see :class:`Binning`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

Interpolation = Literal["bilinear", "pv"]


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
        """``bins / (hi - lo)``: the bin of v is ``floor((v - lo) * scale)`` (``hi`` clipped to the last bin)."""
        return self.bins / (self.hi - self.lo)

    def index(self, values: np.ndarray) -> np.ndarray:
        """Bin of each value (intp, same shape), clipped to ``[0, bins - 1]``."""
        idx = np.floor((np.asarray(values, dtype=np.float64) - self.lo) * self.scale).astype(np.intp)
        return np.clip(idx, 0, self.bins - 1)


def joint_histogram_reference(fixed_values: np.ndarray, moving_values: np.ndarray, fixed_binning: Binning,
                              moving_binning: Binning, weights: np.ndarray | None = None) -> np.ndarray:
    """Plain joint histogram of paired values (n,), shape (fixed bins, moving bins) (a reference for tests)."""
    h = np.zeros((fixed_binning.bins, moving_binning.bins))
    np.add.at(h, (fixed_binning.index(fixed_values), moving_binning.index(moving_values)),
              1.0 if weights is None else weights)
    return h


class JointHistogram:
    """Joint histograms of ``(fixed(x), moving(T(x)))`` for many transforms T at one resolution.

    Parameters
    ----------
    fixed : ndarray, shape (Hf, Wf)
        Fixed image at this resolution.
    moving : ndarray, shape (Hm, Wm)
        Moving image at this resolution.
    fixed_binning, moving_binning : Binning
        Usually over the full-resolution images' ranges.
    factor : int
        Pyramid factor f of both images: level pixel ``[r, c]`` is centred at full-resolution
        ``(f c + (f - 1) / 2, f r + (f - 1) / 2)``; transforms are in full-resolution pixels.
    center : (cx, cy)
        Rotation centre in full-resolution (col, row) pixels.
    interpolation : {'bilinear', 'pv'}
        Bilinear intensity interpolation (binned afterwards) or partial-volume weights.
    samples : int, optional
        Use at most this many fixed pixels, a random subset drawn once with ``seed``.
    seed : int
        Seed of the subset.
    """

    def __init__(self, fixed: np.ndarray, moving: np.ndarray, fixed_binning: Binning, moving_binning: Binning, *,
                 factor: int = 1, center: tuple[float, float], interpolation: Interpolation = "bilinear",
                 samples: int | None = None, seed: int = 0):
        fixed = np.asarray(fixed, dtype=np.float64)
        self.moving = np.ascontiguousarray(moving, dtype=np.float64)
        self.fixed_binning, self.moving_binning = fixed_binning, moving_binning
        self.interpolation = interpolation
        self.factor = int(factor)
        self.center = (float(center[0]), float(center[1]))
        self.shape = (fixed_binning.bins, moving_binning.bins)
        self.n_cells = fixed_binning.bins * moving_binning.bins
        Hf, Wf = fixed.shape
        rows, cols = np.mgrid[0:Hf, 0:Wf]
        flat = np.arange(Hf * Wf)
        if samples is not None and samples < Hf * Wf:
            flat = np.sort(np.random.default_rng(seed).choice(Hf * Wf, size=int(samples), replace=False))
        self.n_samples = len(flat)
        f, o = self.factor, (self.factor - 1) / 2.0
        X = f * cols.ravel()[flat] + o
        Y = f * rows.ravel()[flat] + o
        cx, cy = self.center
        # positions relative to the centre, in moving-level pixels, as one (2, n) array: the
        # transform of all samples is then a single 2 x 2 matrix product
        self._P = np.ascontiguousarray(np.stack([(X - cx) / f, (Y - cy) / f]))
        self._offset = o
        fixed_bins = fixed_binning.index(fixed.ravel()[flat])
        self.fixed_bins = fixed_bins
        self._fbk = fixed_bins * moving_binning.bins  # combined-index base of each sample
        Hm, Wm = self.moving.shape
        self._Hm, self._Wm = Hm, Wm
        self._hi = np.array([[Wm - 1.0], [Hm - 1.0]])
        self._hi0 = np.array([[Wm - 2], [Hm - 2]])
        self._mbins_last = moving_binning.bins - 1
        m = np.zeros(Hm * Wm + Wm + 1)  # padded so that the neighbours of every pixel exist
        m[: Hm * Wm] = (self.moving.ravel() - moving_binning.lo) * moving_binning.scale  # in bin units
        if interpolation == "bilinear":
            # bilinear value at pixel k + (fu, fv) = A + fu Dx + fv (Dy + fu Dxy), one table row per pixel,
            # so that one gather fetches all four coefficients of every sample
            k = np.arange(Hm * Wm)
            A, R, D, DR = m[k], m[k + 1], m[k + Wm], m[k + Wm + 1]
            self._table = np.ascontiguousarray(np.stack([A, R - A, D - A, DR - D - R + A]))
        elif interpolation == "pv":
            mb = np.zeros(Hm * Wm + Wm + 1, dtype=np.intp)
            mb[: Hm * Wm] = moving_binning.index(self.moving).ravel()
            k = np.arange(Hm * Wm)
            self._table = np.ascontiguousarray(np.stack([mb[k], mb[k + 1], mb[k + Wm], mb[k + Wm + 1]]))
        else:
            raise ValueError(f"interpolation must be 'bilinear' or 'pv', got {interpolation!r}")

    def _positions(self, theta) -> np.ndarray:
        tx, ty, angle = (float(t) for t in theta)
        a = math.radians(angle)
        c, s = math.cos(a), math.sin(a)
        f, o = self.factor, self._offset
        UV = np.array([[c, -s], [s, c]]) @ self._P
        UV += np.array([[(self.center[0] + tx - o) / f], [(self.center[1] + ty - o) / f]])
        return UV

    def positions(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """Moving-level positions (u, v) = (col, row) of the samples under ``theta = (tx, ty, angle)``."""
        UV = self._positions(theta)
        return UV[0], UV[1]

    def overlap(self, theta) -> float:
        """Fraction of the samples whose ``T(x)`` lies inside the moving image."""
        u, v = self.positions(theta)
        return float(np.mean((u >= 0) & (u <= self._Wm - 1) & (v >= 0) & (v <= self._Hm - 1)))

    def __call__(self, theta) -> tuple[np.ndarray, int]:
        """Joint histogram for ``theta = (tx, ty, angle)`` and the number of samples inside the moving image.

        Returns
        -------
        h : ndarray, shape (fixed bins, moving bins), float64
            Counts (bilinear) or summed partial-volume weights (pv); rows = fixed bins.
        n_inside : int
        """
        UV = self._positions(theta)
        # clip positions into the image so that every gather stays in the array; a sample is
        # inside (0 <= u <= W - 1, 0 <= v <= H - 1) iff clipping did not move it
        C = np.minimum(np.maximum(UV, 0.0), self._hi)
        inside = (C == UV).all(axis=0)
        n_inside = int(np.count_nonzero(inside))
        if n_inside == 0:
            return np.zeros(self.shape), 0
        C0 = np.minimum(C.astype(np.intp), self._hi0)  # u = W - 1 interpolates with weight 1 on the last column
        F = C - C0
        fu, fv = F[0], F[1]
        i = C0[1] * self._Wm
        i += C0[0]
        G = self._table.take(i, axis=1)
        K = self.n_cells
        if self.interpolation == "bilinear":
            val = G[2] + fu * G[3]
            val *= fv
            val += G[0]
            val += fu * G[1]
            idx = val.astype(np.intp)  # in bin units, >= 0
            np.minimum(idx, self._mbins_last, out=idx)
            idx += self._fbk
            idx = np.where(inside, idx, K)  # outside samples go to a dropped extra cell
            h = np.bincount(idx, minlength=K + 1)[:K].astype(np.float64)
        else:
            # four weighted bincounts (one per neighbour) are ~3x faster than one on the concatenation
            fbk = self._fbk
            gu = 1.0 - fu
            gv = (1.0 - fv) * inside
            fv = fv * inside
            h = np.bincount(fbk + G[0], weights=gu * gv, minlength=K)
            h += np.bincount(fbk + G[1], weights=fu * gv, minlength=K)
            h += np.bincount(fbk + G[2], weights=gu * fv, minlength=K)
            h += np.bincount(fbk + G[3], weights=fu * fv, minlength=K)
        return h.reshape(self.shape), n_inside
