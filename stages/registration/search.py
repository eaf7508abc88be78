"""Coarse exhaustive search for the self-check, 2D and 3D: the measure on a grid of rigid transforms.

On a small copy of both images (smaller side ~``SEARCH_SIDE`` pixels: of the fixed sampling region, if given, and its
samples only; ``SEARCH_BINS`` bins, nearest neighbour, at most ``SEARCH_SAMPLES`` samples), scored with JT of order 2
(histogram weights, closed form) whatever the registration's measure: a detector of basins, not the objective. All
translations of one rotation are one ``np.bincount`` (the moving bins on a canvas whose padding holds an "outside" bin).
It answers the capture, content, prominence and flatness questions of the self-check (docs/registration.md)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from topomatch.stages.registration.histogram import Binning
from topomatch.stages.registration.image import Image, fill_holes, foreground_mask
from topomatch.stages.registration.transform import euler_matrix, n_angles

SEARCH_SIDE = 24
"""Target smaller side (pixels) of the search copy of the images."""
SEARCH_BINS = 16
SEARCH_SAMPLES = 4000
"""Most fixed samples of the search copy (a fixed-seed subset beyond: a 3D copy holds ~40,000 pixels)."""


def batch_jensen_tsallis2(h: np.ndarray) -> np.ndarray:
    """JT (order 2, histogram weights) of a stack of joint histograms (B, fixed bins, moving bins): (B,), the value
    of :func:`~.divergence.jensen_tsallis_histogram` (tested); NaN for an empty histogram."""
    rows = h.sum(axis=2)
    N = rows.sum(axis=1)
    cols = h.sum(axis=1)
    q = np.einsum("bij,bij->bi", h, h)
    with np.errstate(invalid="ignore", divide="ignore"):
        first = np.where(rows > 0, q / np.where(rows > 0, rows, 1.0), 0.0).sum(axis=1) / N
        return first - np.einsum("bj,bj->b", cols, cols) / (N * N)


def search_spacing(images: list[Image], region: np.ndarray | None = None) -> float:
    """The spacing that brings the images' smaller physical extent (the first's: ``region``'s box) to ~``SEARCH_SIDE`` pixels."""
    held = [np.flatnonzero(region.any(axis=tuple(set(range(region.ndim)) - {k}))) for k in range(region.ndim)] \
        if region is not None and region.any() else None  # the indices the region holds along each array axis
    sizes = [[h[-1] - h[0] + 1 for h in held][::-1] if held else images[0].size] + [im.size for im in images[1:]]
    return min(float(min(np.asarray(n) * np.asarray(im.spacing))) for n, im in zip(sizes, images)) / SEARCH_SIDE


def _accepted(raw: np.ndarray, overlaps: np.ndarray, min_overlap: float) -> np.ndarray:
    """The scores ``raw``, ``-inf`` where fewer than ``min_overlap`` of the samples (or none) are inside."""
    return np.where((overlaps >= min_overlap) & (overlaps > 0) & np.isfinite(raw), raw, -np.inf)


class SearchImages:
    """Fixed and moving image at the search resolution, ready to score many transforms at once: transforms in
    physical units about ``center`` (d,), ``-inf`` with fewer than ``min_overlap`` of the fixed samples inside the
    moving image; each image block-averaged by the integer factor per axis that comes closest below ``spacing`` (default:
    :func:`search_spacing`); the fixed samples: the blocks holding a pixel of ``region`` (bool, ``fixed``'s shape), or all."""

    def __init__(self, fixed: Image, moving: Image, *, center, min_overlap: float, spacing: float | None = None,
                 region: np.ndarray | None = None):
        region = region if region is not None and region.any() else None  # an empty region: every pixel
        spacing = search_spacing([fixed, moving], region) if spacing is None else spacing
        factors = [[max(1, int(spacing // s)) for s in im.spacing] for im in (fixed, moving)]
        fixed_small, self.moving_small = fixed.shrink(factors[0]), moving.shrink(factors[1])
        self.spacing, self.dim, self.center = spacing, fixed.dim, np.asarray(center, dtype=np.float64)
        self.min_overlap = float(min_overlap)
        fb, mb = Binning.of(fixed.data, SEARCH_BINS), Binning.of(moving.data, SEARCH_BINS)
        self.K, self._moving_bins = fb.bins * mb.bins, mb.bins
        flat = np.arange(fixed_small.data.size) if region is None else np.flatnonzero(
            fixed.with_data(region).shrink(factors[0]).data)  # the blocks holding a region pixel
        if len(flat) > SEARCH_SAMPLES:
            flat = np.sort(np.random.default_rng(0).choice(flat, SEARCH_SAMPLES, replace=False))
        self._P = (fixed_small.points(flat) - self.center).T  # (d, n)
        self._fbk = (fb.index(fixed_small.data.ravel()[flat]) * mb.bins).astype(np.int32)  # int32: half the traffic
        self.n_samples = self._P.shape[1]
        self._fixed_small, self._flat = fixed_small, flat  # the content test's, made when it asks (content_overlap)
        self._inv = np.linalg.inv(self.moving_small.index_matrix)
        self._moving_bins_small = mb.index(self.moving_small.data)
        self._pad = -1

    def step_vectors(self, steps: np.ndarray) -> np.ndarray:
        """Physical translations (b, d) of whole search-pixel steps (b, d) of the moving search copy."""
        return np.asarray(steps) @ self.moving_small.index_matrix.T

    def _canvas(self, pad: int) -> None:
        """(Re)build the padded moving bins (outside: ``K``) with at least ``pad`` cells a side."""
        if pad <= self._pad:
            return
        bins = np.pad(self._moving_bins_small.astype(np.int32), pad, constant_values=self.K)
        self._pad, self._bins_canvas = pad, bins.ravel()
        self._strides = np.cumprod((1,) + bins.shape[::-1][:-1])  # per ITK axis

    def _cells(self, theta: np.ndarray, steps: np.ndarray) -> np.ndarray:
        """Canvas cell of the nearest moving sample of every fixed sample at ``theta`` moved by each row of
        ``steps`` (b, d) whole search pixels: (b, n)."""
        k = n_angles(self.dim)
        q = euler_matrix(theta[:k]) @ self._P + (self.center + theta[k:] - np.asarray(self.moving_small.origin))[:, None]
        U = np.floor(self._inv @ q + 0.5).astype(np.intp)  # (d, n) moving search indices (ties up: shift-exact)
        low = U.min(axis=1) + steps.min(axis=0)
        high = U.max(axis=1) + steps.max(axis=0) - np.asarray(self.moving_small.size) + 1
        self._canvas(max(0, int((-low).max()), int(high.max())))
        base = ((U + self._pad) * self._strides[:, None]).sum(axis=0)
        return base.astype(np.int32)[None, :] + (steps @ self._strides).astype(np.int32)[:, None]

    def scores_and_overlaps(self, theta: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """JT of order 2 (NaN without samples inside) and the fraction of the samples inside, (b,) each."""
        K, b = self.K, len(steps)
        cells = self._cells(np.asarray(theta, dtype=np.float64), np.asarray(steps, dtype=np.intp))
        idx = self._bins_canvas.take(cells)  # int32 and in place: the 2D search 50 -> 40 ms (same counts)
        idx += self._fbk
        np.minimum(idx, K, out=idx)  # outside samples: the extra cell K of each row
        idx += ((K + 1) * np.arange(b, dtype=np.int32))[:, None]
        h = np.bincount(idx.ravel(), minlength=(K + 1) * b).reshape(b, K + 1)[:, :K]
        h = h.reshape(b, -1, self._moving_bins).astype(np.float64)
        return batch_jensen_tsallis2(h), h.sum(axis=(1, 2)) / self.n_samples

    def score(self, theta: np.ndarray, *, min_overlap: float | None = None) -> float:
        """JT of order 2 of one transform (``-inf`` below ``min_overlap``, default: the instance's)."""
        values, inside = self.scores_and_overlaps(theta, np.zeros((1, self.dim), dtype=np.intp))
        return float(_accepted(values, inside, self.min_overlap if min_overlap is None else min_overlap)[0])

    def content_overlap(self, theta: np.ndarray) -> float:
        """Fraction of the fixed content mapped onto the moving content (Otsu foregrounds, holes filled: round 33)."""
        cells = self._cells(np.asarray(theta, dtype=np.float64), np.zeros((1, self.dim), dtype=np.intp))[0]
        fixed = fill_holes(foreground_mask(self._fixed_small), cross=True).ravel()[self._flat]
        moving = np.pad(fill_holes(foreground_mask(self.moving_small), cross=True), self._pad).ravel()
        return np.count_nonzero(moving[cells] & fixed) / max(1, int(np.count_nonzero(fixed)))


@dataclass(frozen=True, eq=False)
class GridSearch:
    """A scored grid of transforms: parameters ``thetas`` (B, p), their search scores ``raw`` (B,; NaN without a
    sample inside) and fractions of the samples inside ``overlaps`` (B,), the grid's translation step ``spacing``
    (physical units); the first ``n_coarse`` rows are the regular grid, the rest polished points; ``min_overlap``:
    the overlap bound of :attr:`values`; ``images``: the search copy that scored them."""

    thetas: np.ndarray
    raw: np.ndarray
    overlaps: np.ndarray
    spacing: float
    n_coarse: int
    min_overlap: float
    images: SearchImages | None = None

    def values_at(self, min_overlap: float) -> np.ndarray:
        """The scores, ``-inf`` where fewer than ``min_overlap`` of the samples are inside."""
        return _accepted(self.raw, self.overlaps, min_overlap)

    @property
    def values(self) -> np.ndarray:
        return self.values_at(self.min_overlap)

    def prominence(self, value: float) -> float:
        """``(value - median) / MAD`` over the finite scores of the regular grid (inf when it is flat, -inf if
        none is finite)."""
        coarse = self.values[: self.n_coarse]
        finite = coarse[np.isfinite(coarse)]
        if len(finite) == 0 or not math.isfinite(value):
            return -math.inf
        median = float(np.median(finite))
        if (mad := float(np.median(np.abs(finite - median)))) <= 0:
            return math.inf if value > median else 0.0
        return (value - median) / mad


def grid_search(images: SearchImages, rotations: np.ndarray, translation_at: Callable[[np.ndarray], np.ndarray], *,
                steps: int, half_width: float, polish: int = 10, polish_rotations=((),)) -> GridSearch:
    """Score every rotation (rows of ``rotations``, Euler angles) x a ``steps``^d translation grid of half-width
    about ``half_width`` (whole search pixels) about ``translation_at(angles)``; then polish the ``polish``
    best cells (at the images' overlap bound) with a grid one search pixel apart about each (up to 2 pixels
    away), at each rotation offset of ``polish_rotations`` (peaks of multimodal pairs are narrower than a cell).
    The rows are the coarse grid followed by the polished points."""
    d = images.dim
    step = max(1, round(2.0 * half_width / max(1, steps - 1) / images.spacing))  # search pixels between cells
    k = np.rint((np.arange(steps) - (steps - 1) / 2.0) * step).astype(np.intp)
    parts = [_score_cube(images, np.r_[angles, translation_at(angles)], k) for angles in np.atleast_2d(rotations)]
    n_coarse = sum(len(p[0]) for p in parts)
    coarse = GridSearch(*(np.concatenate([p[i] for p in parts]) for i in range(3)), 0.0, n_coarse, images.min_overlap)
    half = np.arange(-min(step // 2, 2), min(step // 2, 2) + 1)  # at most 5 per axis: 125 translations in 3D
    for i in np.argsort(-coarse.values, kind="stable")[:polish]:
        if not math.isfinite(coarse.values[i]):
            break
        for offset in polish_rotations:
            if step == 1 and not np.any(offset):
                continue  # the coarse point itself
            centre = coarse.thetas[i].copy()
            centre[: len(offset)] += offset
            parts.append(_score_cube(images, centre, half))
    spacing = float(np.min(np.linalg.norm(images.step_vectors(np.eye(d, dtype=np.intp)), axis=1))) * step
    return GridSearch(*(np.concatenate([p[i] for p in parts]) for i in range(3)), spacing, n_coarse,
                      images.min_overlap, images)


def _score_cube(images: SearchImages, centre: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, ...]:
    """``centre`` translated by every d-tuple of whole search-pixel steps ``k`` (s,): thetas (s^d, p), raw scores
    and overlaps (s^d,)."""
    d = images.dim
    steps = np.array(list(itertools.product(k, repeat=d)), dtype=np.intp).reshape(-1, d)
    thetas = np.repeat(centre[None, :], len(steps), axis=0)
    thetas[:, -d:] += images.step_vectors(steps)
    return (thetas, *images.scores_and_overlaps(centre, steps))


def directions(p: int) -> np.ndarray:
    """Unit directions of a p-dimensional space, one of each opposite pair: the axes and the diagonals of
    every pair of axes (and, for p <= 3, of every triple), shape (m, p)."""
    vectors = [v for v in itertools.product((-1, 0, 1), repeat=p)
               if v > (0,) * p and (p <= 3 or sum(map(abs, v)) <= 2)]
    out = np.array(vectors, dtype=np.float64)
    return out / np.linalg.norm(out, axis=1)[:, None]


def flatness(score: Callable[[np.ndarray], float], theta: np.ndarray, *, dim: int, reach: float,
             radius: float) -> tuple[float, np.ndarray]:
    """How little ``score`` falls from its maximum ``theta`` in its flattest direction, relative to its steepest:
    near 0 when the images do not determine some combination of the parameters (translation along a straight edge
    or stripes, the rotation of a disc).

    Directions are unit vectors of ``(arcs, translation)`` space, each angle as the arc at ``radius`` (the RMS
    radius of the content): :func:`directions` (axes and diagonals), translations (every 10 degrees in 2D, the 13
    directions of 3-space in 3D) and the pure rotations. The drop along u is ``score(theta) - mean(score(theta +-
    reach u))``: at ``reach`` a determined optimum has fallen in every direction, an undetermined one has not in its
    flat direction. Returns the smallest drop over the largest (clipped to [0, 1]) and the flattest direction (p,)."""
    theta = np.asarray(theta, dtype=np.float64)
    k, p = n_angles(dim), len(theta)
    here = score(theta)
    a = np.radians(np.arange(0, 180, 10))  # 2D: every 10 degrees; 3D: the 13 directions of 3-space
    translations = np.column_stack([np.cos(a), np.sin(a)]) if dim == 2 else directions(3)
    dirs = np.vstack([directions(p), np.hstack([np.zeros((len(translations), k)), translations]), np.eye(p)[:k]])
    if not math.isfinite(here):
        return 0.0, dirs[0]
    unit = np.r_[[1.0 / radius] * k, [1.0] * dim]  # arc -> radians; translations as they are
    around = np.array([[score(theta + sign * reach * u * unit) for sign in (1.0, -1.0)] for u in dirs])
    far = np.where(np.isfinite(around).all(axis=1), here - around.mean(axis=1), np.nan)
    if not np.isfinite(far).any() or np.nanmax(far) <= 0:
        return 0.0, dirs[0]
    flattest = int(np.nanargmin(far))
    return float(np.clip(far[flattest] / np.nanmax(far), 0.0, 1.0)), dirs[flattest]
