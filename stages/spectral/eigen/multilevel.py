"""Decimate, solve the coarse problem exactly, prolong the eigenvectors, refine by LOBPCG + AMG."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from topomatch.stages.spectral.eigen.block_krylov import shift_invert_pairs
from topomatch.stages.spectral.eigen.lobpcg import lobpcg_pairs
from topomatch.stages.spectral.eigen.problem import NotConverged, Problem, Raw


def _barycentric_prolongation(V: np.ndarray, Vc: np.ndarray, Fc: np.ndarray) -> sp.csr_matrix:
    """(n, nc) interpolation: each fine vertex from the closest point on the coarse mesh (barycentric)."""
    import igl

    _, I, C = igl.point_mesh_squared_distance(V, Vc, Fc)
    I = np.asarray(I, dtype=np.int64).ravel()
    T = Fc[I]
    A, B, Cc = Vc[T[:, 0]], Vc[T[:, 1]], Vc[T[:, 2]]
    L = np.asarray(igl.barycentric_coordinates(np.ascontiguousarray(C), np.ascontiguousarray(A),
                                               np.ascontiguousarray(B), np.ascontiguousarray(Cc)))
    L = np.clip(np.nan_to_num(L, nan=1.0 / 3.0), 0.0, None)
    L /= L.sum(axis=1, keepdims=True)
    n = V.shape[0]
    rows = np.repeat(np.arange(n), 3)
    return sp.csr_matrix((L.ravel(), (rows, T.ravel())), shape=(n, Vc.shape[0]))


def multilevel_pairs(prob: Problem, nev: int, *, tol: float, maxiter: int, V: np.ndarray | None,
                F: np.ndarray | None, seed: int, sigma: float | None, coarse_vertices: int,
                backend: str) -> Raw:
    if V is None or F is None:
        raise NotConverged("the multilevel method needs the mesh (V and F)")
    from topomatch.stages.mesh.decimate import simplify_to_target
    from topomatch.stages.mesh.geometry import double_areas_and_sq_lengths
    from topomatch.stages.spectral.laplacian import _assemble, _components

    target = min(coarse_vertices, prob.n // 4)
    if target < 100:
        raise NotConverged(f"mesh too small for multilevel ({prob.n} vertices; needs >= 400)")
    Vc, Fc, _ = simplify_to_target(V, F, 2 * target)
    s, dbl = double_areas_and_sq_lengths(Vc, Fc)
    keep = dbl > 0
    Fc = Fc[keep]
    Qc, Kc = _assemble(Vc.shape[0], Fc, s[keep], dbl[keep])
    if _components(Qc)[0] != 1 or not np.all(Kc.diagonal() > 0):
        raise NotConverged("the decimated mesh is disconnected or degenerate")
    coarse = Problem(Qc, Kc)
    p = nev + 1
    raw = shift_invert_pairs(coarse, p, tol=1e-4, maxiter=maxiter, V=Vc, seed=seed, sigma=None, backend=backend)
    P = _barycentric_prolongation(V, Vc, Fc)
    X0 = P @ raw.vectors
    fine = lobpcg_pairs(prob, nev, tol=tol, maxiter=maxiter, V=V, seed=seed, sigma=sigma, X0=X0)
    return Raw(fine.values, fine.vectors, fine.iterations, fine.n_solves + raw.n_solves, fine.shift)



def solve(prob: Problem, nev: int, opts, V: np.ndarray | None, F: np.ndarray | None) -> Raw:
    """The ``multilevel`` method (module docstring of :mod:`topomatch.stages.spectral.eigen`)."""
    return multilevel_pairs(prob, nev, tol=opts.tol, maxiter=opts.maxiter, V=V, F=F, seed=opts.seed,
                            sigma=opts.sigma, coarse_vertices=opts.coarse_vertices, backend=opts.backend)
