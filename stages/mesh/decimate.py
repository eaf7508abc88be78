"""Quadric edge-collapse decimation with fast-simplification.

fast-simplification (a wrapper of Sven Forstmann's *Fast-Quadric-Mesh-Simplification*)
collapses, in up to 100 sweeps, every edge whose quadric error is below the
threshold ``1e-9 * (sweep + 3) ** agg`` and stops as soon as the face count is at
most the target. What it guarantees, and what this module adds:

- **Never above the target when it stops early**: it stops at the first collapse
  that brings the count to ``<= target``. A collapse removes two faces in the
  interior (so a closed mesh with an odd target ends at ``target - 1``) and one
  to a few at a border or a fan, so the result is ``target`` or a few faces below.
- **Not reaching the target at all** is possible: the threshold is in absolute
  (squared length) units, so a mesh with a bounding-box diagonal of 1000 decimated
  with ``agg=7`` stops far above a small target, and a small ``agg`` (< 5) stops
  early on any mesh; border-to-interior collapses are never done. This module
  therefore (a) maps the mesh to a bounding-box diagonal of 1 centred at the
  origin before decimating and back afterwards, which makes the result
  independent of the units, and (b) repeats the decimation on its own result
  (up to ``MAX_PASSES`` passes, while it makes progress). If the count is still
  above ``target + tolerance`` a :class:`~topomatch.pipeline.errors.StageError` says so.
  ``tolerance = max(2, 1% of the target)`` (:func:`target_tolerance`).
- **Topology is not protected**: the collapses do not check the link condition,
  so at strong reductions the result can have non-manifold edges or a changed
  Euler characteristic (e.g. the bundled low-resolution cat at 10% of its
  faces). The result reports the Euler characteristic before and after and the
  number of non-manifold edges after; run ``clean`` and check the topology when it
  matters.

Unreferenced vertices are dropped from the result. fast-simplification keeps the
mesh being simplified in C++ globals, so calls are serialised with a lock
(threads of one process must not decimate concurrently; processes may).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
from pydantic import Field, model_validator

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.mesh.topology import edge_incidence

#: Upper bound on the passes of fast-simplification over its own result.
MAX_PASSES = 10

# fast_simplification._simplify works on process-global buffers (load -> simplify -> return).
_FAST_SIMPLIFICATION_LOCK = threading.Lock()


class DecimateParams(Params):
    """Parameters of :func:`decimate`: exactly one of ``target_faces`` and ``ratio``."""

    target_faces: int | None = Field(None, ge=4, title="faces after decimation", description="number of faces to keep (at least 4, a tetrahedron)")
    ratio: float | None = Field(None, gt=0, le=1, allow_inf_nan=False,
                                description="fraction of the faces to keep, in (0, 1]")
    aggressiveness: float = Field(7.0, gt=0, le=20, allow_inf_nan=False,
                                  description="fast-simplification 'agg': how fast the collapse threshold grows; "
                                              "smaller keeps the shape better but may stop above the target (< 5)")

    @model_validator(mode="after")
    def _exactly_one_target(self) -> "DecimateParams":
        if (self.target_faces is None) == (self.ratio is None):
            given = "both" if self.target_faces is not None else "neither"
            raise ValueError(f"give exactly one of target_faces and ratio ({given} given)")
        return self

    def target_for(self, n_faces: int) -> int:
        """The target face count for a mesh with ``n_faces`` faces (``round(ratio * n_faces)``, at least 4)."""
        if self.target_faces is not None:
            return self.target_faces
        return max(4, int(round(self.ratio * n_faces)))


def target_tolerance(target: int) -> int:
    """Allowed distance of the final face count from ``target``: ``max(2, floor(0.01 * target))``."""
    return max(2, int(0.01 * target))


@dataclass(frozen=True, eq=False)
class DecimateResult(StageResult):
    """A decimated mesh.

    Attributes
    ----------
    mesh : Mesh
        The decimated mesh, without unreferenced vertices (same name as the input).
    faces_before, faces_after : int
        Face counts of the input and the result.
    target : int
        The requested face count.
    passes : int
        Passes of fast-simplification (0 when the input already had at most ``target`` faces).
    euler_before, euler_after : int
        Euler characteristic V - E + F of the input and the result.
    nonmanifold_edges_after : int
        Edges of the result with more than two faces.
    """

    mesh: Mesh
    faces_before: int
    faces_after: int
    target: int
    passes: int
    euler_before: int
    euler_after: int
    nonmanifold_edges_after: int

    def summary(self) -> dict:
        return {
            "faces_before": self.faces_before,
            "faces_after": self.faces_after,
            "target": self.target,
            "vertices": self.mesh.n_vertices,
            "passes": self.passes,
            "euler_before": self.euler_before,
            "euler_after": self.euler_after,
            "nonmanifold_edges_after": self.nonmanifold_edges_after,
        }


def _euler_and_nonmanifold(F: np.ndarray) -> tuple[int, int]:
    E, counts = edge_incidence(F)
    return int(np.unique(F).size - E.shape[0] + F.shape[0]), int((counts > 2).sum())


def simplify_to_target(V: np.ndarray, F: np.ndarray, target: int, *, aggressiveness: float = 7.0,
                       max_passes: int = MAX_PASSES) -> tuple[np.ndarray, np.ndarray, int]:
    """Decimate ``(V, F)`` to about ``target`` faces with fast-simplification.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions.
    F : (m, 3) int64
        Triangles.
    target : int
        Face count to reach.
    aggressiveness : float
        fast-simplification's ``agg``.
    max_passes : int
        Maximum number of passes over the previous result.

    Returns
    -------
    V : (k, 3) float64
        Positions of the referenced vertices of the result (in the input's units).
    F : (l, 3) int64
        Triangles of the result; ``l <= target`` unless fast-simplification stalled.
    passes : int
        Passes done (0 when ``m <= target``).
    """
    import fast_simplification
    import igl

    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    if F.shape[0] <= target:
        return V, F, 0
    lo, hi = V.min(axis=0), V.max(axis=0)
    center = (lo + hi) / 2.0
    scale = float(np.linalg.norm(hi - lo)) or 1.0
    P, T = (V - center) / scale, F
    passes = 0
    while passes < max_passes and T.shape[0] > target:
        n_before = T.shape[0]
        with _FAST_SIMPLIFICATION_LOCK:
            P, T = fast_simplification.simplify(P, T, target_count=target, agg=aggressiveness)
        T = np.asarray(T, dtype=np.int64)
        passes += 1
        if T.shape[0] >= n_before:
            break
    P = np.asarray(P, dtype=np.float64) * scale + center
    NV, NF, _, _ = igl.remove_unreferenced(P, T)
    return (np.ascontiguousarray(NV, dtype=np.float64), np.ascontiguousarray(NF, dtype=np.int64).reshape(-1, 3),
            passes)


def decimate_mesh(mesh: Mesh, target: int, *, aggressiveness: float = 7.0) -> DecimateResult:
    """Decimate ``mesh`` to ``target`` faces (see the module docstring for the guarantees).

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64.
    target : int
        Face count to reach; a mesh with at most ``target`` faces is returned unchanged.
    aggressiveness : float
        fast-simplification's ``agg``.

    Returns
    -------
    DecimateResult

    Raises
    ------
    StageError
        If the face count stays above ``target + target_tolerance(target)``.
    """
    V, F, passes = simplify_to_target(mesh.V, mesh.F, target, aggressiveness=aggressiveness)
    if F.shape[0] > target + target_tolerance(target):
        raise StageError(f"{mesh.name}: fast-simplification stopped at {F.shape[0]} faces, above the target "
                         f"{target} (from {mesh.n_faces}, {passes} passes, aggressiveness {aggressiveness}); "
                         "raise decimate.aggressiveness or the target")
    out = Mesh(V, F, name=mesh.name) if passes else mesh
    euler_before, _ = _euler_and_nonmanifold(mesh.F)
    euler_after, nonmanifold = _euler_and_nonmanifold(out.F)
    return DecimateResult(
        mesh=out,
        faces_before=mesh.n_faces,
        faces_after=out.n_faces,
        target=target,
        passes=passes,
        euler_before=euler_before,
        euler_after=euler_after,
        nonmanifold_edges_after=nonmanifold,
    )


@stage("decimate", params=DecimateParams, version=1, consumes=("mesh",), produces=("mesh",))
def decimate(mesh: Mesh, *, params: DecimateParams) -> DecimateResult:
    """Decimate to a target face count (fast-simplification quadric edge collapse)."""
    return decimate_mesh(mesh, params.target_for(mesh.n_faces), aggressiveness=params.aggressiveness)
