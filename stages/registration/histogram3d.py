"""Joint intensity histograms of a fixed volume and a rigidly transformed moving volume, in physical space.

The 3D counterpart of :class:`~topomatch.stages.registration.histogram.JointHistogram`, with the same
interface (``h, n_inside = histogram(theta)``, ``n_samples``, ``overlap(theta)``), so that
:class:`~topomatch.stages.registration.objective.Objective` and every measure of
:mod:`~topomatch.stages.registration.divergence` work on it unchanged. Everything that does not
depend on the transform is done once:

- **samples**: ``samples`` voxels of the fixed volume (all of them, or a fixed-seed random subset,
  optionally restricted to a mask), each moved by a fixed random sub-voxel offset (``jitter``: the
  sample positions then do not line up with either grid, which removes the grid-alignment ripples
  of interpolated similarity measures); their physical positions relative to the rotation centre,
  their fixed intensities (trilinear) and bins;
- **moving volume** in bin units, flattened, with the physical-to-index map of its grid.

One evaluation of ``theta = (ax, ay, az, tx, ty, tz)`` (:mod:`~topomatch.stages.registration.transform3d`)
is one 3 x 3 matrix product to moving indices, eight gathers of trilinear interpolation, and two
weighted ``np.bincount`` calls on the combined index ``fixed_bin * moving_bins + moving_bin``: the
interpolated moving value is split linearly between its two nearest bin centres (first-order
B-spline Parzen window), so the histogram, and every measure of it, is a continuous function of the
parameters. Samples that fall outside the moving grid (the convex hull of its voxel centres) are
left out and counted.
"""

from __future__ import annotations

import copy

import numpy as np

from topomatch.stages.registration.histogram import Binning
from topomatch.stages.registration.histogram3d_kernel import joint_histogram
from topomatch.stages.registration.transform3d import euler_matrix
from topomatch.stages.registration.volume import Volume


def trilinear(data: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Trilinear interpolation of ``data`` (nk, nj, ni) at continuous indices ``idx`` (3, n) in (i, j, k)
    order; returns the values (n,) and the ``inside`` mask (n,) (meaningless values outside)."""
    nk, nj, ni = data.shape
    hi = np.array([[ni - 1.0], [nj - 1.0], [nk - 1.0]])
    C = np.minimum(np.maximum(idx, 0.0), hi)
    inside = (C == idx).all(axis=0)
    C0 = np.minimum(C.astype(np.intp), np.maximum(hi.astype(np.intp) - 1, 0))
    F = C - C0
    flat = np.ascontiguousarray(data, dtype=np.float64).ravel()
    return _trilinear_flat(flat, C0, F, ni, ni * nj, data.shape), inside


def _trilinear_flat(flat: np.ndarray, C0: np.ndarray, F: np.ndarray, si: int, sk: int, shape) -> np.ndarray:
    nk, nj, ni = shape
    di = 1 if ni > 1 else 0
    dj = si if nj > 1 else 0
    dk = sk if nk > 1 else 0
    base = C0[2] * sk + C0[1] * si + C0[0]
    fx, fy, fz = F[0], F[1], F[2]
    v000, v100 = flat[base], flat[base + di]
    v010, v110 = flat[base + dj], flat[base + dj + di]
    v001, v101 = flat[base + dk], flat[base + dk + di]
    v011, v111 = flat[base + dk + dj], flat[base + dk + dj + di]
    a = v000 + fx * (v100 - v000)
    b = v010 + fx * (v110 - v010)
    c = v001 + fx * (v101 - v001)
    d = v011 + fx * (v111 - v011)
    a += fy * (b - a)
    c += fy * (d - c)
    a += fz * (c - a)
    return a


class VolumeHistogram:
    """Joint histograms of ``(fixed(p), moving(T(p)))`` over fixed sample points p, for many T.

    Parameters
    ----------
    fixed, moving : Volume
        The two volumes at this pyramid level (any grids, physical geometry as read).
    fixed_binning, moving_binning : Binning
        Usually over the full-resolution volumes' ranges.
    center : array_like, shape (3,)
        Rotation centre c of ``T(p) = R (p - c) + c + t`` (mm).
    samples : int, optional
        At most this many fixed voxels (a random subset drawn once with ``seed``).
    mask : ndarray of bool, optional
        Fixed voxels (of this level's grid) that may be sampled.
    jitter : bool
        Move each sample by a fixed random offset within its voxel.
    seed : int
    """

    def __init__(self, fixed: Volume, moving: Volume, fixed_binning: Binning, moving_binning: Binning, *,
                 center, samples: int | None = None, mask: np.ndarray | None = None, jitter: bool = True,
                 seed: int = 0):
        rng = np.random.default_rng(seed)
        self.fixed_binning, self.moving_binning = fixed_binning, moving_binning
        self.center = np.asarray(center, dtype=np.float64)
        self.shape = (fixed_binning.bins, moving_binning.bins)
        self.n_cells = fixed_binning.bins * moving_binning.bins
        self.factor = 1  # for Objective (lengths here are millimetres, not level pixels)
        flat = np.flatnonzero(mask.ravel()) if mask is not None else np.arange(fixed.data.size)
        if len(flat) == 0:
            raise ValueError("the fixed mask selects no voxel")
        if samples is not None and samples < len(flat):
            flat = np.sort(rng.choice(flat, size=int(samples), replace=False))
        nk, nj, ni = fixed.shape
        k, rem = np.divmod(flat, nj * ni)
        j, i = np.divmod(rem, ni)
        idx = np.stack([i, j, k]).astype(np.float64)
        if jitter:
            idx += rng.uniform(-0.5, 0.5, size=idx.shape)
            idx = np.clip(idx, 0.0, np.array([[ni - 1.0], [nj - 1.0], [nk - 1.0]]))
        values, _ = trilinear(fixed.data, idx)
        self.n_samples = idx.shape[1]
        self._P = np.ascontiguousarray((fixed.physical(idx.T) - self.center).T)  # (3, n) sample positions, about c
        self.fixed_bins = fixed_binning.index(values)
        self._fbk = np.ascontiguousarray(self.fixed_bins * moving_binning.bins, dtype=np.int64)
        self.moving = moving
        self._inv = np.linalg.inv(moving.index_matrix)
        self._origin = np.asarray(moving.origin)
        mk, mj, mi = moving.shape
        self._hi = np.array([[mi - 1.0], [mj - 1.0], [mk - 1.0]])
        self._hi0 = np.maximum(self._hi.astype(np.intp) - 1, 0)
        self._strides = (mi, mi * mj)
        self._mshape = moving.shape
        self._mflat = np.ascontiguousarray((moving.data.ravel() - moving_binning.lo) * moving_binning.scale - 0.5)
        self._bmax = moving_binning.bins - 1

    def shuffled(self, seed: int = 0) -> "VolumeHistogram":
        """The same samples with their fixed intensities paired with other samples' (a fixed-seed permutation):
        the histograms of two volumes that share no structure, with these marginals and this sample count."""
        other = copy.copy(self)
        other._fbk = np.random.default_rng(seed).permutation(self._fbk)
        return other

    def _index_map(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """``A`` (3, 3) and ``b`` (3,) with moving continuous index ``A p + b`` of a sample at ``p`` (about c)."""
        th = np.asarray(theta, dtype=np.float64)
        A = self._inv @ euler_matrix(th[0], th[1], th[2])
        b = self._inv @ (self.center + th[3:6] - self._origin)
        return A, b

    def positions(self, theta) -> np.ndarray:
        """Continuous moving indices (3, n) in (i, j, k) order of the samples under ``theta``."""
        A, b = self._index_map(theta)
        U = A @ self._P
        U += b[:, None]
        return U

    def overlap(self, theta) -> float:
        """Fraction of the samples whose ``T(p)`` lies inside the moving grid."""
        U = self.positions(theta)
        return float(np.mean(((U >= 0) & (U <= self._hi)).all(axis=0)))

    def __call__(self, theta) -> tuple[np.ndarray, int]:
        """Joint histogram (fixed bins, moving bins) for ``theta`` and the number of samples inside.

        One compiled pass (:mod:`~topomatch.stages.registration.histogram3d_kernel`) when numba is
        installed, else :meth:`histogram_numpy` (the same arithmetic)."""
        if joint_histogram is None:
            return self.histogram_numpy(theta)
        A, b = self._index_map(theta)
        mk, mj, mi = self._mshape
        h0, h1, n_inside = joint_histogram(A, b, self._P, self._mflat, mi, mj, mk, self._fbk, self._bmax, self.n_cells)
        K = self.n_cells
        return (h0[:K] + h1[:K]).reshape(self.shape), int(n_inside)

    def histogram_numpy(self, theta) -> tuple[np.ndarray, int]:
        """:meth:`__call__` in numpy: the reference of the compiled kernel, and its fallback."""
        U = self.positions(theta)
        C = np.minimum(np.maximum(U, 0.0), self._hi)
        inside = (C == U).all(axis=0)
        n_inside = int(np.count_nonzero(inside))
        if n_inside == 0:
            return np.zeros(self.shape), 0
        C0 = np.minimum(C.astype(np.intp), self._hi0)
        F = C - C0
        si, sk = self._strides
        b = _trilinear_flat(self._mflat, C0, F, si, sk, self._mshape)  # in bin units, centres at integers
        np.clip(b, 0.0, self._bmax, out=b)
        b0 = np.minimum(b.astype(np.intp), max(self._bmax - 1, 0))
        w = b - b0
        w *= inside
        w0 = inside - w
        idx = b0 + self._fbk
        K = self.n_cells
        h = np.bincount(idx, weights=w0, minlength=K + 1)[:K]
        h += np.bincount(idx + 1, weights=w, minlength=K + 1)[:K]
        return h.reshape(self.shape), n_inside
