"""LOBPCG preconditioned by an algebraic multigrid V-cycle: no factorisation, O(nnz) memory."""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as sla

from topomatch.stages.spectral.eigen.problem import NotConverged, Problem, Raw, auto_shift, rayleigh_estimate, start_block


def _amg_preconditioner(prob: Problem, sigma: float) -> sla.LinearOperator:
    import pyamg

    S = (prob.Q - sigma * prob.K).tocsr()
    ml = pyamg.smoothed_aggregation_solver(S, B=np.ones((prob.n, 1)), max_coarse=300)
    return ml.aspreconditioner(cycle="V")


def lobpcg_pairs(prob: Problem, nev: int, *, tol: float, maxiter: int, V: np.ndarray | None, seed: int,
            sigma: float | None, X0: np.ndarray | None = None) -> Raw:
    import warnings

    p = nev + 1
    if prob.n < 5 * (p + 1):
        raise NotConverged(f"n = {prob.n} is too small for LOBPCG with {p} vectors and a constraint")
    sigma = auto_shift(prob, V) if sigma is None else float(sigma)
    M = _amg_preconditioner(prob, sigma)
    count = [0]

    def precond(X):
        count[0] += X.shape[1] if X.ndim == 2 else 1
        return M @ X

    Mop = sla.LinearOperator((prob.n, prob.n), matvec=precond, matmat=precond, dtype=np.float64)
    X = start_block(prob, p, V, seed) if X0 is None else X0
    X = prob.k_orthonormalize(X)
    if X.shape[1] < p:
        X = np.column_stack([X, np.random.default_rng(seed).standard_normal((prob.n, p - X.shape[1]))])
    # lobpcg stops on ||r||_2 <= its tol; ours is ||r||_{D^-1} / theta <= tol, and
    # ||r||_{D^-1} <= ||r||_2 / sqrt(min d). Start from a Rayleigh-quotient estimate of theta and
    # restart (from the current vectors, with a tighter tol) while our criterion is not met.
    est = rayleigh_estimate(prob, X)
    tol2 = tol * est * np.sqrt(prob.d.min())
    iterations = 0
    for _ in range(4):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            w, Xv, hist = sla.lobpcg(prob.Q, X, B=prob.K, M=Mop, Y=prob.c[:, None], tol=tol2, maxiter=maxiter,
                                     largest=False, retResidualNormsHistory=True)
        iterations += len(hist)
        res_all = prob.residuals(Xv, w)
        order = np.argsort(w)[:nev]
        res = res_all[order]
        if np.all(res <= tol) or iterations >= maxiter:
            break
        X = Xv
        tol2 *= 0.5 * tol / float(res.max())
    w, Xv = w[order], Xv[:, order]
    Xv = prob.deflate(Xv)
    Xv = Xv / np.sqrt(np.einsum("ij,ij->j", Xv, prob.K @ Xv))
    res = prob.residuals(Xv, w)
    if not np.all(res <= 10 * tol):
        raise NotConverged(f"LOBPCG stopped after {iterations} iterations with residuals "
                            f"{np.array2string(res, precision=2)} (tol {tol:g})")
    return Raw(w, Xv, iterations, count[0], sigma)



def solve(prob: Problem, nev: int, opts, V: np.ndarray | None, F: np.ndarray | None) -> Raw:
    """The ``lobpcg`` method (module docstring of :mod:`topomatch.stages.spectral.eigen`)."""
    return lobpcg_pairs(prob, nev, tol=opts.tol, maxiter=opts.maxiter, V=V, seed=opts.seed, sigma=opts.sigma)
