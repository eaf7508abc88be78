"""The image container of the registration stages: a 2D float64 array indexed [row, col] plus
the physical size of a pixel.

Coordinates used everywhere in :mod:`topomatch.stages.registration`: a point is ``x = (col, row)`` in
pixel units (ITK's index order: x first), the centre of pixel ``[r, c]`` is ``(c, r)``, and the
rotation centre of an image of ``H`` rows and ``W`` columns is ``((W - 1) / 2, (H - 1) / 2)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Image:
    """A 2D grey-level image.

    Attributes
    ----------
    data : ndarray, shape (H, W), float64
        Intensities, indexed ``[row, col]``, C-contiguous, finite, not constant.
    spacing : tuple of float
        Physical pixel size ``(row_spacing, col_spacing)`` (e.g. mm) as read from the file;
        ``(1.0, 1.0)`` for formats without spacing (PNG). Registration works in pixel units.
    name : str
        File name without its suffix (for tables and figures).
    source : str
        Where the image came from (a file, ``'slice 30 of file'``, ``'misalign(...)'``).
    """

    data: np.ndarray
    spacing: tuple[float, float] = (1.0, 1.0)
    name: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        data = np.ascontiguousarray(self.data, dtype=np.float64)
        if data.ndim != 2:
            raise ValueError(f"Image.data must be 2D [row, col], got shape {data.shape}")
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "spacing", (float(self.spacing[0]), float(self.spacing[1])))

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``: rows, columns."""
        return self.data.shape  # type: ignore[return-value]

    @property
    def center(self) -> tuple[float, float]:
        """The rotation centre ``(cx, cy) = ((W - 1) / 2, (H - 1) / 2)`` in (col, row) pixels."""
        return image_center(self.shape)

    def with_data(self, data: np.ndarray, *, name: str | None = None, source: str | None = None) -> "Image":
        """The same image metadata with other pixels."""
        return Image(data, self.spacing, self.name if name is None else name, self.source if source is None else source)


def image_center(shape: tuple[int, int]) -> tuple[float, float]:
    """Centre ``((W - 1) / 2, (H - 1) / 2)`` of an image of shape ``(H, W)``, as (col, row)."""
    H, W = shape
    return ((W - 1) / 2.0, (H - 1) / 2.0)
