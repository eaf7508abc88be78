"""Sampling an image between its pixels, in 2D and 3D: N-linear values and resampling onto another grid.

Positions are continuous indices in ITK order (``(i, j[, k])``, pixel ``data[j, i]`` at ``(i, j)``). A
position is **inside** when ``0 <= index <= size - 1`` on every axis (inside the hull of the pixel
centres, where every N-linear neighbour exists); the samplers return that mask, and the registration
leaves the other samples out of its histograms. :func:`resample` (outputs, figures, synthetic
misalignments) fills them with ``fill``.
"""

from __future__ import annotations

import numpy as np

from topomatch.stages.registration.image import Image
from topomatch.stages.registration.transform import RigidTransform


def linear(data: np.ndarray, index: np.ndarray, order: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Values of ``data`` (array order) at continuous indices ``index`` (d, n) in ITK order, and ``inside`` (n,).

    ``order`` 1 is N-linear interpolation; 3 a cubic B-spline (``scipy.ndimage.map_coordinates``; clipped to
    the data's range). Positions outside are clamped to the border (their values mean nothing)."""
    from scipy.ndimage import map_coordinates

    index = np.asarray(index, dtype=np.float64)
    hi = (np.asarray(data.shape[::-1]) - 1.0)[:, None]
    inside = ((index >= 0) & (index <= hi)).all(axis=0)
    values = map_coordinates(np.asarray(data, dtype=np.float64), index[::-1], order=order, mode="nearest",
                             prefilter=order > 1)
    if order > 1:
        values = np.clip(values, data.min(), data.max())
    return values, inside


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
