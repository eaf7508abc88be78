"""Cross-check of the spectral and level-set stages against libigl's own functions.

- Eigenpairs: topomatch's :func:`~topomatch.stages.spectral.laplacian.laplacian` +
  :func:`~topomatch.stages.spectral.eigen.smallest_eigenpairs` against the libigl
  path ``igl.cotmatrix`` + ``igl.massmatrix(FULL)`` + ``igl.spectra.eigs`` (smallest
  magnitude) on the same mesh: relative eigenvalue differences and, for each
  eigenvector whose eigenvalue is simple, 1 - |<phi_ours, phi_igl>_K| (all but the last pair).
- Level sets: :func:`~topomatch.stages.reeb.level_sets.isolines` against ``igl.isolines``
  on the same function and level values: per-level length difference and the
  largest distance between matching segment midpoints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage


def libigl_eigenpairs(V: np.ndarray, F: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The libigl reference: ascending eigenvalues (k,) and vectors (n, k) of -L phi = lambda M phi."""
    import igl
    import igl.spectra

    L = -igl.cotmatrix(V, F)
    M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_FULL)
    U, S = igl.spectra.eigs(L.tocsc(), M.tocsc(), k, igl.spectra.EIGS_TYPE_SM)
    order = np.argsort(S)
    return np.asarray(S)[order], np.asarray(U)[:, order]


def isoline_differences(V, F, f, levels) -> dict:
    """Per-level length and midpoint differences between our iso-curves and ``igl.isolines``."""
    import igl
    from scipy.spatial import cKDTree

    from topomatch.stages.reeb.level_sets import isolines

    ours = isolines(V, F, f, levels)
    iV, iE, I = igl.isolines(V, F, f, levels[1:-1])
    ref = iV[iE]
    len_ours = np.linalg.norm(ours.segments[:, 1] - ours.segments[:, 0], axis=1)
    len_ref = np.linalg.norm(ref[:, 1] - ref[:, 0], axis=1)
    n_levels = len(levels) - 1
    per_level_ours = np.bincount(ours.level, weights=len_ours, minlength=n_levels + 1)[1:n_levels]
    per_level_ref = np.bincount(I + 1, weights=len_ref, minlength=n_levels + 1)[1:n_levels]
    scale = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    keep_o, keep_r = len_ours > 1e-12 * scale, len_ref > 1e-12 * scale
    mid_o, mid_r = ours.segments.mean(axis=1)[keep_o], ref.mean(axis=1)[keep_r]
    gap = 0.0
    if len(mid_o) and len(mid_r):
        gap = max(cKDTree(mid_r).query(mid_o)[0].max(), cKDTree(mid_o).query(mid_r)[0].max())
    return {
        "isoline_segments": int(keep_o.sum()),
        "isoline_segments_igl": int(keep_r.sum()),
        "isoline_length_rel_diff": float(np.max(np.abs(per_level_ours - per_level_ref) / np.maximum(per_level_ref, 1e-300))),
        "isoline_midpoint_gap_rel": gap / scale,
    }


class LibiglReferenceParams(Params):
    """Parameters of the ``libigl_reference`` stage."""

    eigenpairs: int = Field(6, ge=2, le=50, description="number of smallest eigenpairs compared")


@dataclass(frozen=True, eq=False)
class LibiglReferenceResult(StageResult):
    values: np.ndarray
    values_igl: np.ndarray
    vector_misfit: np.ndarray
    isolines: dict
    seconds: float
    seconds_igl: float

    def summary(self) -> dict:
        rel = np.abs(self.values[1:] - self.values_igl[1:]) / np.abs(self.values_igl[1:])
        out = {"lambda2": float(self.values[1]), "lambda2_igl": float(self.values_igl[1]),
               "eigenvalue_rel_diff_max": float(rel.max()),
               "eigenvector_misfit_max": float(np.nanmax(self.vector_misfit)) if np.any(np.isfinite(self.vector_misfit)) else None,
               "seconds": self.seconds, "seconds_igl": self.seconds_igl}
        out.update(self.isolines)
        return out


@stage("libigl_reference", params=LibiglReferenceParams, version=1, consumes=("mesh", "function", "level_sets"))
def libigl_reference(mesh, function, level_sets, *, params: LibiglReferenceParams) -> LibiglReferenceResult:
    """Compare our eigenpairs with igl.spectra.eigs and our level sets with igl.isolines."""
    import time

    from topomatch.stages.spectral.eigen import smallest_eigenpairs
    from topomatch.stages.spectral.laplacian import laplacian

    k = params.eigenpairs
    t = time.perf_counter()
    lap = laplacian(mesh, "full")
    ours = smallest_eigenpairs(lap.Q, lap.K, k, V=mesh.V, F=mesh.F)
    seconds = time.perf_counter() - t
    t = time.perf_counter()
    values_igl, vectors_igl = libigl_eigenpairs(mesh.V, mesh.F, k)
    seconds_igl = time.perf_counter() - t
    K = lap.K
    misfit = np.full(k, np.nan)
    gaps = np.diff(values_igl)
    for i in range(1, k - 1):  # the last pair may belong to a multiplet cut off at k
        simple = min(gaps[i - 1], gaps[i]) > 1e-6 * values_igl[i]
        if simple:
            a, b = ours.vectors[:, i], vectors_igl[:, i]
            cos = abs(a @ (K @ b)) / np.sqrt((a @ (K @ a)) * (b @ (K @ b)))
            misfit[i] = 1.0 - cos
    return LibiglReferenceResult(ours.values, values_igl, misfit,
                                 isoline_differences(mesh.V, mesh.F, function.values, level_sets.values),
                                 seconds, seconds_igl)
