"""Sampling an image between its pixels, in 2D and 3D: N-linear values and resampling onto another grid.

Positions are continuous indices in ITK order (``(i, j[, k])``, pixel ``data[j, i]`` at ``(i, j)``). A position is
**inside** when ``0 <= index <= size - 1`` on every axis (inside the hull of the pixel centres, where every N-linear
neighbour exists); the samplers return that mask, and the registration leaves the other samples out of its histograms.
:func:`resample` (outputs, figures, synthetic misalignments) fills them with ``fill``."""

from __future__ import annotations

import itertools

import numpy as np

from topomatch.stages.registration.image import Image
from topomatch.stages.registration.transform import RigidTransform


def corners(index: np.ndarray, size) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 2^d N-linear neighbours of continuous indices ``index`` (d, n) (ITK order) in a grid of ``size``
    (ITK order): a list of (weights (n,), flat C-order indices (n,)), the weights of each position summing to 1.
    Positions are clamped to the grid (a position outside gets its nearest border's neighbours)."""
    hi = (np.asarray(size) - 1.0)[:, None]
    U = np.clip(np.asarray(index, dtype=np.float64), 0.0, hi)
    C0 = np.minimum(U.astype(np.intp), np.maximum(hi.astype(np.intp) - 1, 0))
    F = U - C0
    strides = np.cumprod((1,) + tuple(size)[:-1])[:, None]
    bits = [np.array(corner)[:, None] for corner in itertools.product((0, 1), repeat=len(size))]
    return [(np.prod(np.where(bit == 1, F, 1.0 - F), axis=0),
             (np.minimum(C0 + bit, hi.astype(np.intp)) * strides).sum(axis=0)) for bit in bits]


def inside(index: np.ndarray, size) -> np.ndarray:
    """Whether each continuous index (d, n) lies within the hull of the pixel centres of a grid of ``size``."""
    return ((index >= 0) & (index <= (np.asarray(size) - 1.0)[:, None])).all(axis=0)


def linear(data: np.ndarray, index: np.ndarray, order: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Values of ``data`` (array order) at continuous indices ``index`` (d, n) in ITK order, and ``inside`` (n,).

    ``order`` 1 is N-linear interpolation (numpy: importing scipy costs a 3D registration a tenth of a
    second); 3 a cubic B-spline (``scipy.ndimage.map_coordinates``, clipped to the data's range). Positions
    outside are clamped to the border (their values mean nothing)."""
    index = np.asarray(index, dtype=np.float64)
    size = data.shape[::-1]
    if order == 1:
        flat = np.asarray(data, dtype=np.float64).ravel()
        return sum(w * flat[c] for w, c in corners(index, size)), inside(index, size)
    from scipy.ndimage import map_coordinates

    values = map_coordinates(np.asarray(data, dtype=np.float64), index[::-1], order=order, mode="nearest")
    return np.clip(values, data.min(), data.max()), inside(index, size)


def resample(moving: Image, transform: RigidTransform, reference: Image, *, order: int = 1, fill: float = 0.0,
             flat: np.ndarray | None = None, chunk: int = 1 << 20) -> np.ndarray:
    """``moving(T(p))`` at the pixels p of ``reference``'s grid (default all: shape ``reference.shape``; else the
    pixels of flat indices ``flat``, shape of ``flat``), ``fill`` where ``T(p)`` leaves the moving grid."""
    targets = np.arange(reference.data.size) if flat is None else np.asarray(flat).ravel()
    out = np.empty(len(targets))
    for start in range(0, len(targets), chunk):
        part = targets[start: start + chunk]
        index = moving.continuous_index(transform.apply(reference.points(part))).T
        values, inside = linear(moving.data, index, order)
        out[start: start + chunk] = np.where(inside, values, fill)
    return out.reshape(reference.shape if flat is None else np.shape(flat))
