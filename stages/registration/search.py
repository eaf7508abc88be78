"""Coarse exhaustive search: the measure on a grid of rigid transforms, for the self-check.

The optimisers are local; the self-check of :mod:`~topomatch.stages.registration.register` asks two
global questions of the result, both answered by one batched evaluation of a grid of transforms
(every ``check.probes`` angles over the full circle x a ``check.grid`` x ``check.grid`` translation
grid over the search box) on a small copy of the images (smaller side ~24 px, 16 bins,
nearest-neighbour sampling):

* **capture**: which grid transforms away from the result score best (they are refined on the
  first level and compared with the result there);
* **content overlap**: the fraction of the fixed image's content (Otsu foreground) that the result
  maps onto the moving image's content; below ``check.min_content`` the result rests on too little
  shared content (e.g. a moving image shifted until only a strip of it remains), even where the
  moving *grid* overlaps enough;
* **prominence**: how far the result stands out of the landscape, in median absolute deviations
  above the grid's median. Two images with no shared content (noise, an unrelated image, a sliver
  of overlap) have no distinct optimum, whatever the optimiser returns.

The grid is scored with Jensen-Tsallis of order 2 with histogram weights (the thesis's measure,
closed form ``sum_ij h_ij^2 / (N h_i.) - sum_j (h_.j / N)^2``) whatever the registration's
measure is: a detector of basins, not the objective. All transforms of one angle are one
``np.bincount``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from topomatch.stages.registration.histogram import Binning
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.interpolation import downsample

SEARCH_SIDE = 24
"""Target smaller side (pixels) of the search copy of the images."""
SEARCH_BINS = 16

# the 13 directions of (tx, ty, arc) space, one of each opposite pair: axes, face and body diagonals
_DIRECTIONS = np.array([d for d in np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).reshape(3, -1).T
                        if tuple(d) > (0, 0, 0)], dtype=np.float64)
_DIRECTIONS /= np.linalg.norm(_DIRECTIONS, axis=1)[:, None]
# translations every 10 degrees and the pure rotation
_PLANAR = np.vstack([np.column_stack([np.cos(np.radians(np.arange(0, 180, 10))),
                                      np.sin(np.radians(np.arange(0, 180, 10))), np.zeros(18)]), [[0.0, 0.0, 1.0]]])


def otsu_threshold(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold (Otsu 1979: maximal between-class variance) of the values, on ``bins`` bins.

    Written here (same threshold as SimpleITK's ``OtsuThreshold``, tested) because importing
    SimpleITK costs ~0.2 s, as much as a registration.
    """
    counts, edges = np.histogram(values, bins=bins)
    centers = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(counts)[:-1].astype(np.float64)
    w1 = counts.sum() - w0
    m = np.cumsum(counts * centers)[:-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        between = w0 * w1 * (m / w0 - (m[-1] + counts[-1] * centers[-1] - m) / w1) ** 2
    between = np.where((w0 > 0) & (w1 > 0), between, -1.0)
    return float(edges[1:-1][np.argmax(between)])


def batch_jensen_tsallis2(h: np.ndarray) -> np.ndarray:
    """JT (order 2, histogram weights) of a stack of joint histograms (B, fixed bins, moving bins): (B,).

    Same value as :func:`~topomatch.stages.registration.divergence.jensen_tsallis_histogram` (tested);
    NaN for an empty histogram.
    """
    rows = h.sum(axis=2)
    N = rows.sum(axis=1)
    cols = h.sum(axis=1)
    q = np.einsum("bij,bij->bi", h, h)
    with np.errstate(invalid="ignore", divide="ignore"):
        first = np.where(rows > 0, q / np.where(rows > 0, rows, 1.0), 0.0).sum(axis=1) / N
        return first - np.einsum("bj,bj->b", cols, cols) / (N * N)


class SearchImages:
    """Fixed and moving image at the search resolution, ready to score many transforms at once.

    The moving image's bins sit on a padded canvas whose padding holds an "outside" bin, so a
    sample maps to a histogram cell by one gather and no bounds test; translations of a grid
    are whole search pixels apart, so all transforms of one angle share one rounding of the
    rotated samples and differ by one integer offset each.

    Parameters
    ----------
    fixed, moving : Image
        Full-resolution images; transforms are in full-resolution pixels about ``fixed.center``.
    min_overlap : float
        Transforms with fewer fixed samples inside the moving image score ``-inf``.
    """

    def __init__(self, fixed: Image, moving: Image, *, min_overlap: float):
        smallest = min(min(fixed.shape), min(moving.shape))
        f = self.factor = max(1, smallest // SEARCH_SIDE)
        fixed_small, moving_small = downsample(fixed.data, f), downsample(moving.data, f)
        self.min_overlap = float(min_overlap)
        fb, mb = Binning.of(fixed.data, SEARCH_BINS), Binning.of(moving.data, SEARCH_BINS)
        self.K, self._moving_bins = fb.bins * mb.bins, mb.bins
        Hf, Wf = fixed_small.shape
        rows, cols = np.mgrid[0:Hf, 0:Wf]
        o = self._offset = (f - 1) / 2.0
        cx, cy = self.center = (float(fixed.center[0]), float(fixed.center[1]))
        # sample positions relative to the centre in search-level pixels (2, n)
        self._P = np.stack([(f * cols.ravel() + o - cx) / f, (f * rows.ravel() + o - cy) / f])
        self._fbk = fb.index(fixed_small.ravel()) * mb.bins
        self.n_samples = self._P.shape[1]
        self._fixed_content = (fixed_small > otsu_threshold(fixed_small)).ravel()
        self._moving_small_bins = mb.index(moving_small)
        self._moving_small_content = moving_small > otsu_threshold(moving_small)
        self._pad = -1

    def _canvas(self, pad: int) -> None:
        """(Re)build the padded moving bins (outside: ``K``) and content masks with at least ``pad`` cells a side."""
        if pad <= self._pad:
            return
        Hm, Wm = self._moving_small_bins.shape
        bins = np.full((Hm + 2 * pad, Wm + 2 * pad), self.K, dtype=np.intp)
        bins[pad:pad + Hm, pad:pad + Wm] = self._moving_small_bins
        content = np.zeros(bins.shape, dtype=bool)
        content[pad:pad + Hm, pad:pad + Wm] = self._moving_small_content
        self._pad, self._bins_canvas, self._content_canvas = pad, bins.ravel(), content.ravel()

    def _cells(self, theta: np.ndarray, steps: np.ndarray) -> np.ndarray:
        """Canvas cell of the nearest moving sample of every fixed sample, for ``theta = (tx, ty, angle)``
        translated further by each row of ``steps`` (b, 2) whole search pixels: (b, n)."""
        a = math.radians(float(theta[2]))
        c, s = math.cos(a), math.sin(a)
        f, o = self.factor, self._offset
        RP = np.array([[c, -s], [s, c]]) @ self._P
        u = np.rint(RP[0] + (self.center[0] + theta[0] - o) / f).astype(np.intp)
        v = np.rint(RP[1] + (self.center[1] + theta[1] - o) / f).astype(np.intp)
        Hm, Wm = self._moving_small_bins.shape
        need = max(0, -(u.min() + steps[:, 0].min()), u.max() + steps[:, 0].max() - Wm + 1,
                   -(v.min() + steps[:, 1].min()), v.max() + steps[:, 1].max() - Hm + 1)
        self._canvas(int(need))
        width = Wm + 2 * self._pad
        base = (v + self._pad) * width + (u + self._pad)
        return base[None, :] + (steps[:, 1] * width + steps[:, 0])[:, None]

    def score_steps(self, theta: np.ndarray, steps: np.ndarray, *, min_overlap: float | None = None) -> np.ndarray:
        """JT of order 2 at ``theta`` moved by each row of ``steps`` (b, 2) whole search pixels: (b,).

        ``-inf`` where fewer than ``min_overlap`` (default: the instance's) of the samples are inside.
        """
        min_overlap = self.min_overlap if min_overlap is None else min_overlap
        K, b = self.K, len(steps)
        cells = self._cells(theta, steps)  # first: it sizes the canvas
        idx = self._fbk[None, :] + self._bins_canvas[cells]
        np.minimum(idx, K, out=idx)  # outside samples: the extra cell K of each row
        idx += (K + 1) * np.arange(b)[:, None]
        h = np.bincount(idx.ravel(), minlength=(K + 1) * b).reshape(b, K + 1)[:, :K]
        h = h.reshape(b, -1, self._moving_bins).astype(np.float64)
        inside = h.sum(axis=(1, 2))
        values = batch_jensen_tsallis2(h)
        return np.where((inside >= min_overlap * self.n_samples) & (inside > 0) & np.isfinite(values), values, -np.inf)

    def score(self, theta: np.ndarray, *, min_overlap: float | None = None) -> float:
        """JT of order 2 of one transform (``-inf`` below ``min_overlap``, default: the instance's)."""
        steps = np.zeros((1, 2), dtype=np.intp)
        return float(self.score_steps(np.asarray(theta, dtype=np.float64), steps, min_overlap=min_overlap)[0])

    def content_overlap(self, theta: np.ndarray) -> float:
        """Fraction of the fixed image's content (Otsu foreground) mapped onto the moving image's content."""
        cells = self._cells(np.asarray(theta, dtype=np.float64), np.zeros((1, 2), dtype=np.intp))[0]
        both = np.count_nonzero(self._content_canvas[cells] & self._fixed_content)
        return both / max(1, int(np.count_nonzero(self._fixed_content)))


@dataclass(frozen=True, eq=False)
class GridSearch:
    """A scored grid of transforms.

    Attributes
    ----------
    thetas : ndarray, shape (B, 3)
        ``(tx, ty, angle)`` of every grid transform.
    values : ndarray, shape (B,)
        Their search scores (``-inf`` below the overlap).
    spacing : float
        Translation step of the grid (full-resolution pixels).
    angle_spacing : float
        Angle step of the grid (degrees).
    n_coarse : int
        The first ``n_coarse`` rows are the regular grid, the rest polished points.
    """

    thetas: np.ndarray
    values: np.ndarray
    spacing: float
    angle_spacing: float
    n_coarse: int

    def prominence(self, value: float) -> float:
        """``(value - median) / MAD`` over the finite scores of the regular grid (inf when it is flat, -inf if
        none is finite)."""
        coarse = self.values[: self.n_coarse]
        finite = coarse[np.isfinite(coarse)]
        if len(finite) == 0 or not math.isfinite(value):
            return -math.inf
        median = float(np.median(finite))
        mad = float(np.median(np.abs(finite - median)))
        if mad <= 0:
            return math.inf if value > median else 0.0
        return (value - median) / mad


def flatness(score: Callable[[np.ndarray], float], theta: np.ndarray, *, step: float, reach: float,
             radius: float) -> tuple[float, np.ndarray]:
    """How little ``score`` falls from its maximum ``theta`` in its flattest direction, relative to
    its steepest: near 0 when the images do not determine some combination of the parameters
    (translation along a straight edge or stripes, the rotation of a disc).

    Directions are unit vectors of ``(tx, ty, arc)`` space, the angle as the arc at ``radius``
    pixels (the RMS radius of the fixed image). A quadratic form fitted to the drops
    ``score(theta) - mean(score(theta +- step u))`` over 13 directions (axes, face and body
    diagonals) gives the locally flattest direction (its eigenvector of least curvature); then the
    drop at the longer ``reach`` is measured along it, along translations every 10 degrees and the
    pure rotation, and along the 13. Close to the optimum a cusp and the sampling noise blur the
    curvature; at ``reach`` a determined optimum has fallen in every direction, an undetermined
    one has not in its flat direction.

    Returns
    -------
    ratio : float
        The smallest drop at ``reach`` over the largest (clipped to [0, 1]).
    direction : ndarray, shape (3,)
        The flattest direction ``(tx, ty, arc)``.
    """
    theta = np.asarray(theta, dtype=np.float64)
    here = score(theta)
    if not math.isfinite(here):
        return 0.0, _DIRECTIONS[0]

    def drop(u: np.ndarray, r: float) -> float:
        delta = r * np.array([u[0], u[1], math.degrees(u[2] / radius)])
        around = [score(theta + sign * delta) for sign in (1.0, -1.0)]
        return here - 0.5 * sum(around) if all(map(math.isfinite, around)) else math.nan

    local = np.array([drop(u, step) for u in _DIRECTIONS])
    known = np.isfinite(local)
    candidates = [_DIRECTIONS, _PLANAR]
    if known.sum() >= 6:
        u = _DIRECTIONS[known]
        design = np.column_stack([u[:, 0] ** 2, u[:, 1] ** 2, u[:, 2] ** 2,
                                  2 * u[:, 0] * u[:, 1], 2 * u[:, 0] * u[:, 2], 2 * u[:, 1] * u[:, 2]])
        a = np.linalg.lstsq(design, local[known], rcond=None)[0]
        _, vectors = np.linalg.eigh(np.array([[a[0], a[3], a[4]], [a[3], a[1], a[5]], [a[4], a[5], a[2]]]))
        candidates.append(vectors[:, :1].T)
    directions = np.vstack(candidates)
    far = np.array([drop(u, reach) for u in directions])
    if not np.isfinite(far).any() or np.nanmax(far) <= 0:
        return 0.0, directions[0]
    flattest = int(np.nanargmin(far))
    return float(np.clip(far[flattest] / np.nanmax(far), 0.0, 1.0)), directions[flattest]


def grid_search(images: SearchImages, translation_at: Callable[[float], np.ndarray], *, angles: int, steps: int,
                half_width: float, polish: int = 10) -> GridSearch:
    """Score ``angles`` rotations over the full circle x a ``steps`` x ``steps`` translation grid of
    half-width about ``half_width`` (rounded to whole search pixels) about ``translation_at(angle)``,
    then polish the ``polish`` best grid cells with a finer grid inside each (peaks of multimodal
    pairs are narrower than a cell).

    The returned thetas and values are the coarse grid followed by the polished points.
    """
    f = images.factor
    step = max(1, round(2.0 * half_width / max(1, steps - 1) / f))  # search pixels between grid translations
    k = np.rint((np.arange(steps) - (steps - 1) / 2.0) * step).astype(np.intp)
    angle_step = 360.0 / angles
    thetas, values = [], []
    for angle in np.linspace(-180.0, 180.0, angles, endpoint=False):
        t = translation_at(angle)
        th, v = _score_square(images, np.array([t[0], t[1], angle]), k)
        thetas.append(th)
        values.append(v)
    coarse_thetas, coarse_values = np.vstack(thetas), np.concatenate(values)
    # polish: around each of the best cells, a translation grid one search pixel apart and three
    # more angles between the neighbouring grid angles
    half = np.arange(-(step // 2), step // 2 + 1)
    for i in np.argsort(-coarse_values, kind="stable")[:polish]:
        if not math.isfinite(coarse_values[i]):
            break
        for d_angle in (-angle_step / 4, 0.0, angle_step / 4) if step > 1 else (-angle_step / 4, angle_step / 4):
            th, v = _score_square(images, coarse_thetas[i] + np.array([0.0, 0.0, d_angle]), half)
            thetas.append(th)
            values.append(v)
    return GridSearch(np.vstack(thetas), np.concatenate(values), float(step * f), angle_step, len(coarse_values))


def _score_square(images: SearchImages, centre: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Score ``centre`` translated by every pair of whole search-pixel steps ``k`` (s,): thetas (s^2, 3), values."""
    kx, ky = np.meshgrid(k, k, indexing="ij")
    steps = np.column_stack([kx.ravel(), ky.ravel()])
    f = images.factor
    thetas = np.column_stack([centre[0] + f * steps[:, 0], centre[1] + f * steps[:, 1], np.full(len(steps), centre[2])])
    return thetas, images.score_steps(centre, steps)
