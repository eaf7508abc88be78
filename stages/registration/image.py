"""The image of the registration stages, in 2D and 3D alike: an array plus ITK's physical geometry.

Geometry exactly as ITK / SimpleITK define it, for every dimension ``d`` (2 or 3): the pixel of index ``(i, j[, k])``
(``data[j, i]``, ``data[k, j, i]``: SimpleITK's array order) sits at the physical point::

    p = origin + direction @ diag(spacing) @ (i, j[, k])

``spacing``, ``origin`` and ``direction`` are in ITK's index order (x first), ``direction``'s *columns* are the grid
axes. A PNG has spacing 1, origin 0 and the identity direction, so its physical point of pixel ``[r, c]`` is
``(c, r)``: pixel units. Everything the registration computes (the rotation centre, transforms, errors) is in these
physical coordinates; this module is the only place that converts between indices and points."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Image:
    """A 2D or 3D grey-level image with its physical grid: ``data`` (H, W) or (K, J, I), float64 in SimpleITK's
    array order, C-contiguous; ``spacing`` and ``origin`` (d,): pixel size and the position of pixel 0, ITK order
    ``(x, y[, z])`` (default 1 and 0); ``direction`` (d, d): grid axes as columns (default: identity); ``name``:
    the file name without suffix; ``source``: where the image came from."""

    data: np.ndarray
    spacing: tuple[float, ...] | None = None
    origin: tuple[float, ...] | None = None
    direction: np.ndarray | None = field(default=None)
    name: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        data = np.ascontiguousarray(self.data, dtype=np.float64)
        if data.ndim not in (2, 3):
            raise ValueError(f"Image.data must be 2D [row, col] or 3D [k, j, i], got shape {data.shape}")
        d = data.ndim
        spacing = tuple(float(s) for s in (self.spacing if self.spacing is not None else (1.0,) * d))
        origin = tuple(float(o) for o in (self.origin if self.origin is not None else (0.0,) * d))
        direction = np.eye(d) if self.direction is None else np.asarray(self.direction, dtype=np.float64).reshape(d, d)
        if len(spacing) != d or not all(np.isfinite(spacing)) or min(spacing) <= 0:
            raise ValueError(f"Image.spacing must be {d} positive numbers, got {self.spacing}")
        if len(origin) != d or not all(np.isfinite(origin)):
            raise ValueError(f"Image.origin must be {d} finite numbers, got {self.origin}")
        if not abs(np.linalg.det(direction)) > 1e-6:
            raise ValueError(f"Image.direction is singular: {direction.tolist()}")
        for name, value in (("data", data), ("spacing", spacing), ("origin", origin), ("direction", direction)):
            object.__setattr__(self, name, value)

    @property
    def dim(self) -> int:
        return self.data.ndim

    @property
    def shape(self) -> tuple[int, ...]:
        """The array's shape: ``(H, W)`` or ``(K, J, I)``."""
        return self.data.shape

    @property
    def size(self) -> tuple[int, ...]:
        """Pixels along i, j[, k] (SimpleITK's ``GetSize()``)."""
        return tuple(reversed(self.data.shape))

    @property
    def index_matrix(self) -> np.ndarray:
        """``direction @ diag(spacing)`` (d, d): physical offset per unit of index."""
        return self.direction * np.asarray(self.spacing)[None, :]

    def physical(self, index: np.ndarray) -> np.ndarray:
        """Physical points (n, d) of continuous indices (n, d) in ITK order."""
        return np.asarray(index, dtype=np.float64) @ self.index_matrix.T + np.asarray(self.origin)

    def continuous_index(self, points: np.ndarray) -> np.ndarray:
        """Continuous indices (n, d), ITK order, of physical points (n, d)."""
        return (np.asarray(points, dtype=np.float64) - np.asarray(self.origin)) @ np.linalg.inv(self.index_matrix).T

    @property
    def center(self) -> np.ndarray:
        """Physical centre of the grid (of its corner pixels' box), shape (d,): ``((W-1)/2, (H-1)/2)`` for a PNG."""
        return self.physical((np.asarray(self.size, dtype=np.float64) - 1.0)[None, :] / 2.0)[0]

    def indices(self, flat: np.ndarray | None = None) -> np.ndarray:
        """ITK-order indices (n, d) of the pixels with flat (C-order) indices ``flat`` (default: all)."""
        flat = np.arange(self.data.size) if flat is None else np.asarray(flat)
        return np.stack(np.unravel_index(flat, self.shape)[::-1], axis=1).astype(np.float64)

    def points(self, flat: np.ndarray | None = None) -> np.ndarray:
        """Physical points (n, d) of the pixels with flat indices ``flat`` (default: all)."""
        return self.physical(self.indices(flat))

    def centroid(self) -> np.ndarray:
        """Physical intensity centroid of ``data - min(data)`` (ITK's MOMENTS initialiser), shape (d,)."""
        w = self.data - self.data.min()
        if (total := w.sum()) <= 0:
            return self.center
        axes = range(self.dim)
        index = [w.sum(axis=tuple(a for a in axes if a != ax)) @ np.arange(n) for ax, n in enumerate(self.shape)]
        return self.physical((np.array(index[::-1]) / total)[None, :])[0]

    def with_data(self, data: np.ndarray, *, name: str | None = None, source: str | None = None) -> "Image":
        """The same geometry with other pixels (same shape)."""
        return Image(data, self.spacing, self.origin, self.direction, self.name if name is None else name,
                     self.source if source is None else source)

    def scaled(self, factor: float) -> "Image":
        """The same pixels with spacing and origin times ``factor``: physical coordinates times ``factor``."""
        return Image(self.data, tuple(factor * np.asarray(self.spacing)), tuple(factor * np.asarray(self.origin)),
                     self.direction, self.name, self.source)

    def shrink(self, factors) -> "Image":
        """Block average by integer ``factors`` (ITK order), trailing partial blocks dropped: each pixel the mean of
        its block at the block's physical centre (spacing ``s * f``, origin moved by ``(f - 1) / 2`` pixels)."""
        f = np.array([max(1, min(int(f), n)) for f, n in zip(factors, self.size)])
        if (f == 1).all():
            return self
        m = np.array(self.size) // f
        crop = self.data[tuple(slice(0, int(mi * fi)) for mi, fi in zip(m[::-1], f[::-1]))]
        blocks = crop.reshape([x for mi, fi in zip(m[::-1], f[::-1]) for x in (int(mi), int(fi))])
        data = blocks.mean(axis=tuple(range(1, 2 * self.dim, 2)))
        origin = self.physical(((f - 1.0) / 2.0)[None, :])[0]
        return Image(data, tuple(np.asarray(self.spacing) * f), tuple(origin), self.direction, self.name, self.source)

    def shrink_to(self, spacing: float, min_size: int = 1) -> "Image":
        """:meth:`shrink` by the integer factor per axis that brings the spacing closest to ``spacing`` (never
        finer than native), keeping at least ``min_size`` pixels per axis: a physical-space pyramid level."""
        # per axis the nearest factor, at most the largest keeping min_size pixels (a countdown took hours at 1e-30 mm)
        return self.shrink([min(max(1, int(round(spacing / s))), max(1, n // max(min_size, 1)))
                            for n, s in zip(self.size, self.spacing)])

    def smoothed(self, sigma: float) -> "Image":
        """The same grid blurred by a Gaussian of ``sigma`` physical units along every axis (edges by nearest
        value; :func:`gaussian_blur`)."""
        return self.with_data(gaussian_blur(self.data, [sigma / s for s in self.spacing][::-1]))


def gaussian_blur(data: np.ndarray, sigmas, truncate: float = 4.0) -> np.ndarray:
    """``data`` convolved with a Gaussian of ``sigmas[a]`` pixels along array axis ``a`` (0: none), edges
    repeated: ``scipy.ndimage.gaussian_filter(data, sigmas, mode='nearest', truncate=truncate)`` to rounding
    (tested), in numpy because importing ``scipy.ndimage`` costs a registration 0.12 s."""
    out = np.asarray(data, dtype=np.float64)
    for axis, sigma in enumerate(sigmas):
        if sigma <= 0:
            continue
        r = int(truncate * sigma + 0.5)
        w = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
        w /= w.sum()
        pad = [(r, r) if a == axis else (0, 0) for a in range(out.ndim)]
        padded = np.moveaxis(np.pad(out, pad, mode="edge"), axis, 0)  # a view, the blurred axis first
        n = out.shape[axis]
        out = np.moveaxis(sum(wk * padded[k: k + n] for k, wk in enumerate(w)), 0, axis)
    return out


def otsu_threshold(values: np.ndarray, bins: int = 256) -> float:
    """Otsu's threshold (Otsu 1979: maximal between-class variance) of the values, on ``bins`` bins: SimpleITK's
    ``OtsuThreshold`` (tested) without its import (~0.2 s, as much as a 2D registration)."""
    counts, edges = np.histogram(values, bins=bins)
    centers = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(counts)[:-1].astype(np.float64)
    w1 = counts.sum() - w0
    m = np.cumsum(counts * centers)[:-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        between = w0 * w1 * (m / w0 - (m[-1] + counts[-1] * centers[-1] - m) / w1) ** 2
    between = np.where((w0 > 0) & (w1 > 0), between, -1.0)
    return float(edges[1:-1][np.argmax(between)])


def border(shape) -> np.ndarray:
    """The outermost pixels of a grid of ``shape`` (every face), a bool array of that shape."""
    out = np.ones(shape, dtype=bool)
    out[tuple(slice(1, -1) if n > 2 else slice(0, 0) for n in shape)] = False
    return out


def foreground_mask(image: Image) -> np.ndarray:
    """The image's content (bool, the shape of ``image.data``), from Otsu's two classes and the grid's border.

    The class above the threshold when at most half the border is above it (a bright head on a dark background); the
    class below when at least 90 % of the border is above it (a dark object on a bright background: an inverted image, a
    negative); the whole grid in between (the object fills the frame: no background to tell it from)."""
    above = image.data > otsu_threshold(image.data)
    share = float(above[border(above.shape)].mean())
    return above if share <= 0.5 else ~above if share >= 0.9 else np.ones_like(above)


def grow(mask: np.ndarray, distance: float, spacing=None) -> np.ndarray:
    """``mask`` grown by ``distance`` physical units (default spacing 1: pixels) along every axis (a box of
    half-widths ``distance / spacing`` pixels, rounded: Chebyshev, not Euclidean, distance), by running maxima
    along each axis in numpy (scipy's distance transform would cost a 3D registration a tenth of a second of import)."""
    out = np.asarray(mask, dtype=bool).copy()
    for axis, s in enumerate((1.0,) * out.ndim if spacing is None else spacing[::-1]):  # array axis, its spacing
        r = int(round(distance / s))
        grown = out.copy()
        o, g = np.moveaxis(out, axis, 0), np.moveaxis(grown, axis, 0)  # views, the grown axis first
        for shift in range(1, min(r, len(o) - 1) + 1):
            g[:-shift] |= o[shift:]
            g[shift:] |= o[:-shift]
        out = grown
    return out


def fill_holes(mask: np.ndarray, *, cross: bool = False) -> np.ndarray:
    """``mask`` with every background region that does not reach the grid's border filled: 8- / 26-connected background
    (scipy's ``binary_fill_holes`` with a full structuring element), with ``cross`` 4- / 6-connected (its default)."""
    mask = np.asarray(mask, dtype=bool)
    free = ~mask
    outside = free & border(mask.shape)
    while True:  # geodesic dilation of the border's background inside the background (np.roll's wrap meets the border)
        grown = (np.logical_or.reduce([outside] + [np.roll(outside, s, a) for a in range(mask.ndim) for s in (1, -1)])
                 if cross else grow(outside, 1.0)) & free
        if np.array_equal(grown, outside):
            return ~outside
        outside = grown


def rms_radius(image: Image, mask: np.ndarray | None = None, max_points: int = 100_000) -> float:
    """RMS physical distance of the (masked) pixels from the grid's centre: a rotation by ``d`` radians moves
    them by about ``d * rms_radius`` (how angles and translations are put on one scale)."""
    flat = np.flatnonzero(mask.ravel()) if mask is not None and mask.any() else np.arange(image.data.size)
    pts = image.points(flat[:: max(1, len(flat) // max_points)])
    return float(np.sqrt(np.mean(np.sum((pts - image.center) ** 2, axis=1))))
