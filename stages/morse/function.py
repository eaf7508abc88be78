"""The scalar vertex function that a skeleton is built from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class MorseFunction:
    """A piecewise-linear function on mesh vertices.

    Attributes
    ----------
    values : (n,) float64
        One value per vertex (linearly interpolated over each triangle).
    kind : str
        'mixture', 'euclidean', 'affine', 'fiedler', 'height' or 'geodesic'.
    root : (3,) float64 or None
        A point the skeleton is rooted at (the centroid c of the mixture distance);
        None for functions without one.
    info : dict
        Scalars describing how it was computed (lambda, eigenvalues, ...).
    """

    values: np.ndarray
    kind: str
    root: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        values = np.ascontiguousarray(self.values, dtype=np.float64)
        if values.ndim != 1:
            raise ValueError(f"values must have shape (n,), got {values.shape}")
        object.__setattr__(self, "values", values)


def normalized(values: np.ndarray) -> np.ndarray:
    """(f - min f) / (max f - min f) in [0, 1]; a constant function maps to zeros."""
    values = np.asarray(values, dtype=np.float64)
    lo, hi = values.min(), values.max()
    span = hi - lo
    return (values - lo) / span if span > 0 else np.zeros_like(values)
