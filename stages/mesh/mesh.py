"""The canonical triangle mesh."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh in libigl's native layout.

    Attributes
    ----------
    V : (n, 3) float64, C-contiguous
        Vertex positions.
    F : (m, 3) int64, C-contiguous
        Triangles as vertex indices (0-based).
    name : str
        Short name for tables and figures (usually the file stem).
    closed_manifold : bool or None
        Whether every edge has exactly two faces, when known: set by ``clean`` (from its
        topology report), kept by :meth:`with_vertices`; None = not known (computed where
        needed, e.g. by the Reeb graph, at the cost of one sort of the half-edges).
    """

    V: np.ndarray
    F: np.ndarray
    name: str = field(default="mesh")
    closed_manifold: bool | None = field(default=None)

    def __post_init__(self) -> None:
        V = np.ascontiguousarray(self.V, dtype=np.float64)
        F = np.ascontiguousarray(self.F, dtype=np.int64)
        if V.ndim != 2 or V.shape[1] != 3:
            raise ValueError(f"V must have shape (n, 3), got {V.shape}")
        if F.ndim != 2 or F.shape[1] != 3:
            raise ValueError(f"F must have shape (m, 3), got {F.shape}")
        object.__setattr__(self, "V", V)
        object.__setattr__(self, "F", F)

    @property
    def n_vertices(self) -> int:
        return int(self.V.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.F.shape[0])

    def with_vertices(self, V: np.ndarray) -> "Mesh":
        """Same connectivity, name and closedness, new positions ``V`` (n, 3)."""
        return Mesh(V, self.F, self.name, self.closed_manifold)
