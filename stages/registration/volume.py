"""The volume container of the 3D registration: a float64 array in SimpleITK's ``[k, j, i]`` order
plus the voxel grid's physical geometry (spacing, origin, direction), and the grid operations the
registration needs (physical points of voxels, centre, intensity centroid, block-averaged pyramid).

Geometry, exactly as SimpleITK / ITK define it (LPS millimetres): the voxel of index
``(i, j, k)`` (``data[k, j, i]``) sits at the physical point::

    p = origin + direction @ diag(spacing) @ (i, j, k)

``direction`` is the 3 x 3 matrix whose *columns* are the grid axes in physical space (SimpleITK's
``GetDirection()`` is it, row-major). Everything the registration computes (the rotation centre,
transforms, target registration errors) is in these physical coordinates, so voxel size,
anisotropy and orientation are handled once, here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from topomatch.stages.registration.search import otsu_threshold


@dataclass(frozen=True, eq=False)
class Volume:
    """A 3D grey-level volume with its physical grid.

    Attributes
    ----------
    data : ndarray, shape (nk, nj, ni), float64
        Intensities, ``data[k, j, i]`` (SimpleITK's ``GetArrayFromImage`` order), C-contiguous.
    spacing : (sx, sy, sz)
        Voxel size along the grid axes i, j, k (mm).
    origin : (ox, oy, oz)
        Physical position of voxel (0, 0, 0) (mm, LPS).
    direction : ndarray, shape (3, 3)
        Grid axes as columns (orthonormal for medical images).
    name, source : str
        File name without suffix; where the volume came from.
    """

    data: np.ndarray
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))
    name: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        data = np.ascontiguousarray(self.data, dtype=np.float64)
        if data.ndim != 3:
            raise ValueError(f"Volume.data must be 3D [k, j, i], got shape {data.shape}")
        direction = np.asarray(self.direction, dtype=np.float64).reshape(3, 3)
        if abs(np.linalg.det(direction)) < 1e-6:
            raise ValueError(f"Volume.direction is singular: {direction.tolist()}")
        spacing = tuple(float(s) for s in self.spacing)
        if len(spacing) != 3 or min(spacing) <= 0:
            raise ValueError(f"Volume.spacing must be 3 positive numbers, got {self.spacing}")
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "spacing", spacing)
        object.__setattr__(self, "origin", tuple(float(o) for o in self.origin))

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(nk, nj, ni)``: the array's shape."""
        return self.data.shape  # type: ignore[return-value]

    @property
    def size(self) -> tuple[int, int, int]:
        """``(ni, nj, nk)``: voxels along i, j, k (SimpleITK's ``GetSize()``)."""
        return tuple(reversed(self.data.shape))  # type: ignore[return-value]

    @property
    def index_matrix(self) -> np.ndarray:
        """``direction @ diag(spacing)`` (3, 3): physical offset per unit of (i, j, k)."""
        return self.direction * np.asarray(self.spacing)[None, :]

    def physical(self, index: np.ndarray) -> np.ndarray:
        """Physical points (n, 3) of continuous indices (n, 3) in (i, j, k) order."""
        return np.asarray(index, dtype=np.float64) @ self.index_matrix.T + np.asarray(self.origin)

    def continuous_index(self, points: np.ndarray) -> np.ndarray:
        """Continuous (i, j, k) indices (n, 3) of physical points (n, 3)."""
        inv = np.linalg.inv(self.index_matrix)
        return (np.asarray(points, dtype=np.float64) - np.asarray(self.origin)) @ inv.T

    @property
    def center(self) -> np.ndarray:
        """Physical centre of the grid (the centre of its corner voxels' box), shape (3,)."""
        return self.physical((np.asarray(self.size, dtype=np.float64) - 1.0)[None, :] / 2.0)[0]

    def voxel_points(self, flat: np.ndarray | None = None) -> np.ndarray:
        """Physical points (n, 3) of the voxels with flat (C-order) indices ``flat`` (default: all)."""
        nk, nj, ni = self.shape
        flat = np.arange(nk * nj * ni) if flat is None else np.asarray(flat)
        k, rem = np.divmod(flat, nj * ni)
        j, i = np.divmod(rem, ni)
        return self.physical(np.stack([i, j, k], axis=1).astype(np.float64))

    def centroid(self) -> np.ndarray:
        """Physical intensity centroid of ``data - min(data)`` (ITK's MOMENTS initialiser), shape (3,)."""
        w = self.data - self.data.min()
        total = w.sum()
        if total <= 0:
            return self.center
        nk, nj, ni = self.shape
        idx = np.array([w.sum(axis=(0, 1)) @ np.arange(ni), w.sum(axis=(0, 2)) @ np.arange(nj),
                        w.sum(axis=(1, 2)) @ np.arange(nk)]) / total
        return self.physical(idx[None, :])[0]

    def with_data(self, data: np.ndarray, *, name: str | None = None, source: str | None = None) -> "Volume":
        """The same geometry with other voxels (same shape)."""
        return Volume(data, self.spacing, self.origin, self.direction, self.name if name is None else name,
                      self.source if source is None else source)

    def shrink(self, factors: tuple[int, int, int]) -> "Volume":
        """Block average by ``factors`` along (i, j, k), the trailing partial blocks dropped.

        The voxel ``(i, j, k)`` of the result is the mean of its ``fi x fj x fk`` block, centred at
        the block's physical centre: spacing ``s * f``, origin moved by ``(f - 1) / 2`` voxels.
        """
        fi, fj, fk = (max(1, int(f)) for f in factors)
        if (fi, fj, fk) == (1, 1, 1):
            return self
        nk, nj, ni = self.shape
        mk, mj, mi = max(1, nk // fk), max(1, nj // fj), max(1, ni // fi)
        fk, fj, fi = min(fk, nk), min(fj, nj), min(fi, ni)
        d = self.data[: mk * fk, : mj * fj, : mi * fi].reshape(mk, fk, mj, fj, mi, fi).mean(axis=(1, 3, 5))
        f = np.array([fi, fj, fk], dtype=np.float64)
        origin = self.physical(((f - 1.0) / 2.0)[None, :])[0]
        return Volume(d, tuple(np.asarray(self.spacing) * f), tuple(origin), self.direction, self.name, self.source)

    def smoothed(self, sigma_mm: float) -> "Volume":
        """The same grid, blurred by a Gaussian of standard deviation ``sigma_mm`` (physical mm along every axis;
        ``scipy.ndimage.gaussian_filter``, edges by nearest value)."""
        from scipy.ndimage import gaussian_filter

        sigma = [sigma_mm / s for s in self.spacing][::-1]  # data[k, j, i]
        return self.with_data(gaussian_filter(self.data, sigma, mode="nearest"))

    def shrink_to(self, spacing_mm: float) -> "Volume":
        """:meth:`shrink` by the integer factors that bring each spacing closest to ``spacing_mm``
        without going below the native spacing (a physical-space pyramid level)."""
        factors = tuple(max(1, int(round(spacing_mm / s))) for s in self.spacing)
        return self.shrink(factors)  # type: ignore[arg-type]


def foreground_mask(volume: Volume) -> np.ndarray:
    """Voxels above Otsu's threshold (bool, shape of ``volume.data``): the head / brain of an MR volume."""
    return volume.data > otsu_threshold(volume.data)
