"""Sampling an image at non-integer positions: bilinear values, partial-volume weights, resampling.

Positions are ``(u, v) = (col, row)`` in pixels of the sampled image; pixel ``[r, c]`` is at
``(c, r)``.

**Samples outside the image.** A position is *inside* when ``0 <= u <= W - 1`` and
``0 <= v <= H - 1``, i.e. inside the convex hull of the pixel centres, where all four bilinear
neighbours exist. Everything else is *outside*: the samplers return an ``inside`` mask and the
joint histogram leaves those samples out (they are masked, never filled with a made-up
intensity), so the divergence is computed on the overlap of the two images only; the overlap
fraction is reported and a registration whose overlap falls below a minimum is rejected.
:func:`resample` (for figures, outputs and synthetic misalignments) fills outside pixels with
``fill`` (0 by default, the background of the bundled MRI slices).

**Partial-volume interpolation** (Maes, Collignon et al., IEEE TMI 1997) does not create new
intensities: each sample adds the bilinear weights of its four neighbours to the joint
histogram cells of their own (binned) intensities, which makes the histogram a continuous
function of the transform parameters.
"""

from __future__ import annotations

import numpy as np

from topomatch.stages.registration.image import Image
from topomatch.stages.registration.transform import RigidTransform, grid_points


def bilinear(data: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear interpolation of ``data`` (H, W) at positions (u, v) = (col, row).

    Returns
    -------
    values : ndarray, shape like u
        Interpolated intensities (meaningless where not ``inside``).
    inside : ndarray of bool, shape like u
        ``0 <= u <= W - 1`` and ``0 <= v <= H - 1``.
    """
    H, W = data.shape
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    inside = (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
    u0 = np.clip(np.floor(u), 0, W - 2).astype(np.intp)
    v0 = np.clip(np.floor(v), 0, H - 2).astype(np.intp)
    fu = u - u0
    fv = v - v0
    flat = data.ravel()
    i = v0 * W + u0
    a = flat[i] + fu * (flat[i + 1] - flat[i])
    b = flat[i + W] + fu * (flat[i + W + 1] - flat[i + W])
    return a + fv * (b - a), inside


def partial_volume(shape: tuple[int, int], u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Partial-volume neighbours and weights of positions (u, v) in an image of ``shape`` (H, W).

    Returns
    -------
    index : ndarray of intp, shape (4, n)
        Flat indices of the four neighbours (top-left, top-right, bottom-left, bottom-right).
    weight : ndarray, shape (4, n)
        Bilinear weights, summing to 1 for each sample (0 for samples outside).
    inside : ndarray of bool, shape (n,)
    """
    H, W = shape
    u = np.asarray(u, dtype=np.float64).ravel()
    v = np.asarray(v, dtype=np.float64).ravel()
    inside = (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
    u0 = np.clip(np.floor(u), 0, W - 2).astype(np.intp)
    v0 = np.clip(np.floor(v), 0, H - 2).astype(np.intp)
    fu = u - u0
    fv = v - v0
    i = v0 * W + u0
    index = np.stack([i, i + 1, i + W, i + W + 1])
    weight = np.stack([(1 - fu) * (1 - fv), fu * (1 - fv), (1 - fu) * fv, fu * fv]) * inside
    return index, weight, inside


def resample(moving: Image | np.ndarray, transform: RigidTransform, shape: tuple[int, int], *,
             order: int = 1, fill: float = 0.0) -> np.ndarray:
    """``moving(T(x))`` for every pixel x of a grid of ``shape`` (H, W): the moving image on the fixed grid.

    Parameters
    ----------
    moving : Image or ndarray (Hm, Wm)
    transform : RigidTransform
        Maps fixed-grid points to moving-image points (its centre is normally the fixed grid's).
    shape : (H, W)
        The fixed grid.
    order : {1, 3}
        1: bilinear (:func:`bilinear`); 3: cubic B-spline (``scipy.ndimage.map_coordinates``),
        clipped to the moving image's intensity range.
    fill : float
        Value of pixels whose ``T(x)`` falls outside the moving image.

    Returns
    -------
    ndarray, shape (H, W), float64
    """
    data = moving.data if isinstance(moving, Image) else np.asarray(moving, dtype=np.float64)
    pts = transform.apply(grid_points(shape))
    u, v = pts[:, 0], pts[:, 1]
    if order == 1:
        values, inside = bilinear(data, u, v)
    elif order == 3:
        from scipy.ndimage import map_coordinates

        Hm, Wm = data.shape
        inside = (u >= 0) & (u <= Wm - 1) & (v >= 0) & (v <= Hm - 1)
        values = map_coordinates(data, [v, u], order=3, mode="nearest", prefilter=True)
        values = np.clip(values, data.min(), data.max())
    else:
        raise ValueError(f"order must be 1 (bilinear) or 3 (cubic B-spline), got {order}")
    return np.where(inside, values, fill).reshape(shape)


def downsample(data: np.ndarray, factor: int) -> np.ndarray:
    """Block average of ``data`` (H, W) over ``factor x factor`` blocks, shape (H // f, W // f).

    Pixel ``[r, c]`` of the result covers full-resolution pixels ``f r .. f r + f - 1``, so its
    centre is at full-resolution ``(f c + (f - 1) / 2, f r + (f - 1) / 2)`` (col, row). Rows and
    columns beyond a multiple of ``factor`` are dropped.
    """
    if factor == 1:
        return np.ascontiguousarray(data, dtype=np.float64)
    H, W = data.shape
    h, w = H // factor, W // factor
    if h < 2 or w < 2:
        raise ValueError(f"image of shape {data.shape} is too small for a pyramid level with factor {factor}")
    block = data[: h * factor, : w * factor].reshape(h, factor, w, factor)
    return np.ascontiguousarray(block.mean(axis=(1, 3)))
