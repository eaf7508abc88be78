"""ARPACK (``scipy.sparse.linalg.eigsh``, mode 3) on a factorisation of ``Q - sigma K``: the fallback of
the block Krylov solver, and the ``arpack`` method for many eigenpairs (tens: the spectrum of a shape)."""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as sla

from topomatch.stages.spectral.eigen.problem import NotConverged, Problem, Raw, start_block


def arpack_fallback(prob: Problem, fac, nev: int, tol: float, V, seed: int) -> Raw | None:
    """ARPACK (mode 3) with the same factorisation; the constant is among its k = nev + 1 pairs."""
    count = [0]

    def opinv(b):
        count[0] += 1
        return fac.solve(b)

    op = sla.LinearOperator((prob.n, prob.n), matvec=opinv, dtype=np.float64)
    v0 = prob.deflate(start_block(prob, 1, V, seed))[:, 0]
    try:
        w, X = sla.eigsh(prob.Q, k=nev + 1, M=prob.K, sigma=fac.sigma, OPinv=op, which="LM", v0=v0,
                         tol=tol * 1e-3, maxiter=2000)
    except (sla.ArpackNoConvergence, sla.ArpackError):
        return None
    order = np.argsort(w)
    w, X = w[order][1:], X[:, order][:, 1:]
    X = prob.deflate(X)
    X = X / np.sqrt(np.einsum("ij,ij->j", X, prob.K @ X))
    if np.any(prob.residuals(X, w) > 10 * tol):
        return None
    return Raw(w, X, 0, count[0], fac.sigma)



#: Problems with at most this many vertices go to the dense method instead.
DENSE_BELOW = 400


def window(n: int, nev: int) -> int:
    """The number of pairs ARPACK is asked for: ``k = nev + 1`` plus ``max(8, k / 8)`` (see :func:`solve`)."""
    k = nev + 1
    return min(n - 1, k + max(8, k // 8))


def fits(n: int, nev: int) -> bool:
    """Whether the ``arpack`` method takes an n-vertex problem for nev non-constant pairs."""
    return n > max(DENSE_BELOW, window(n, nev) + 2)


def solve(prob: Problem, nev: int, opts, V: np.ndarray | None, F: np.ndarray | None) -> Raw:
    """The ``arpack`` method: ARPACK in shift-invert mode around ``sigma`` (default: 1 % of the Weyl
    spacing ``4 pi / A`` below zero), on qdldl's LDL^T (its solves are the fastest, and ARPACK needs
    about a hundred of them), asked for a window of extra pairs.

    Lanczos finds the copies of an exactly repeated eigenvalue (symmetric shapes) only through
    round-off, and misses some near the end of the window it is asked for (icospheres: one of the 4
    copies of l = 3 when asked for 16, three of the 9 of l = 4 when asked for 28): it is asked for
    ``max(8, k / 8)`` more than the ``k = nev + 1`` wanted (passes every icosphere case in the tests);
    generic meshes have simple eigenvalues and need none of this. The constant is among ARPACK's pairs
    and is dropped (the caller puts the exact one back). Tiny problems (n <= 400, or too few vertices
    for the window) are left to the dense method.

    With a diagonal (lumped) mass ``K = D`` the problem is solved in standard form,
    ``D^-1/2 Q D^-1/2 psi = lambda psi`` with ``phi = D^-1/2 psi`` (the same eigenvalues; shift-invert
    operator ``D^1/2 (Q - sigma D)^-1 D^1/2``): ARPACK then needs no mass products for its
    D-inner products (about 400 per spectrum of 40 pairs): ~10 % faster on the retrieval spectra
    (40 Watertight meshes decimated to 6,000 faces, measured in process; eigenvalues equal to
    6e-15 relative, vectors to 4e-12).
    """
    from topomatch.stages.spectral.eigen.factorization import ShiftInvert

    n, k = prob.n, nev + 1
    want = window(n, nev)
    if not fits(n, nev):
        raise NotConverged(f"n = {n} is too small for the ARPACK window of {want} pairs")
    sigma = -0.01 * 4.0 * np.pi / prob.area if opts.sigma is None else float(opts.sigma)
    v0 = np.random.default_rng(opts.seed).standard_normal(n)
    try:
        try:
            inv = ShiftInvert(prob.Q, prob.K, sigma, backend="qdldl" if opts.backend == "auto" else opts.backend)
        except ImportError:
            inv = ShiftInvert(prob.Q, prob.K, sigma)
        count = [0]
        # lumped mass: no non-zero off the diagonal (stored zeros off it allowed)
        rows = np.repeat(np.arange(n), np.diff(prob.K.indptr))
        diagonal = not np.any(prob.K.data[prob.K.indices != rows])
        root = np.sqrt(prob.d) if diagonal else None

        def opinv(b):
            count[0] += 1
            return inv.solve(b) if root is None else root * inv.solve(root * np.ravel(b))

        op = sla.LinearOperator((n, n), matvec=opinv, dtype=np.float64)
        if diagonal:  # standard form; A is never applied when OPinv is given (mode 3, M = I)
            identity = sla.LinearOperator((n, n), matvec=lambda x: x, dtype=np.float64)
            vals, vecs = sla.eigsh(identity, k=want, sigma=sigma, OPinv=op, which="LM", v0=v0, tol=1e-10,
                                   return_eigenvectors=True)
            vecs = vecs / root[:, None]
        else:
            vals, vecs = sla.eigsh(prob.Q, k=want, M=prob.K, sigma=sigma, OPinv=op, which="LM", v0=v0, tol=1e-10,
                                   return_eigenvectors=True)
    except (sla.ArpackNoConvergence, sla.ArpackError, RuntimeError, ValueError) as exc:
        raise NotConverged(f"ARPACK failed for {k} eigenpairs ({exc})") from None
    order = np.argsort(np.real(vals))[:k]
    vals, vecs = np.real(vals[order]), np.real(vecs[:, order])
    return Raw(vals[1:], vecs[:, 1:], 0, count[0], sigma)
