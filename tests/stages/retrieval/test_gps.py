"""The GPS distance distributions (Rustamov 2007): the embedding's distances against effective resistance, scale and
bending invariance, discrimination."""

from __future__ import annotations

import igl
import numpy as np
import pytest
import scipy.linalg
import scipy.sparse.linalg

from topomatch.pipeline.errors import StageError
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval import gps
from topomatch.stages.retrieval.catalogue import METHODS
from topomatch.stages.spectral.spectrum import Spectrum, mesh_spectrum


def ellipsoid(a: float, b: float, c: float, level: int = 3) -> Mesh:
    from shapes import icosphere

    sphere = icosphere(level)
    return Mesh(sphere.V * np.array([a, b, c]), sphere.F, name=f"ellipsoid {a}x{b}x{c}")


def full_spectrum(mesh: Mesh) -> tuple[Spectrum, scipy.sparse.spmatrix]:
    """Every eigenpair of the cotangent Laplacian with the lumped Voronoi mass (dense), and the stiffness matrix."""
    L = -igl.cotmatrix(mesh.V, mesh.F)
    M = igl.massmatrix(mesh.V, mesh.F, igl.MASSMATRIX_TYPE_VORONOI)
    values, vectors = scipy.linalg.eigh(L.toarray(), M.toarray())
    mass = M.diagonal()
    return Spectrum(values, vectors, mass, float(mass.sum())), L


def test_the_full_embedding_measures_effective_resistance():
    """Over every eigenpair, |GPS(x) - GPS(y)|^2 = (e_x - e_y)^T L^+ (e_x - e_y): the effective resistance of the
    cotangent Laplacian between x and y (L Phi Lambda^+ Phi^T b = b for b orthogonal to the constants)."""
    mesh = ellipsoid(3, 2, 1, level=2)
    spectrum, L = full_spectrum(mesh)
    G = gps.embedding(spectrum, len(spectrum.values) - 1)
    rng = np.random.default_rng(0)
    n = len(mesh.V)
    grounded = L.tocsc()[1:, 1:]  # vertex 0 held at 0
    for x, y in rng.choice(n, size=(5, 2), replace=False):
        b = np.zeros(n)
        b[x], b[y] = 1.0, -1.0
        u = np.r_[0.0, scipy.sparse.linalg.spsolve(grounded, b[1:])]
        assert np.sum((G[x] - G[y]) ** 2) == pytest.approx(u[x] - u[y], rel=1e-8)


def test_histograms_are_distributions_invariant_to_scale():
    """Scaled and shifted, the same shape: equal up to the eigensolver's tolerance (ARPACK mixes near-equal
    eigenpairs differently; measured 0.009 in L1 of the three histograms), far below another ellipsoid's."""
    mesh = ellipsoid(3, 2, 1)
    params = gps.GPSParams(n_pairs=1 << 14)
    h = gps.gps_histograms(mesh_spectrum(mesh, 20), params)
    assert h.shape == (3 * params.bins,)
    assert np.allclose(h.reshape(3, -1).sum(axis=1), 1.0)
    scaled = Mesh(mesh.V * 7.0 + 3.0, mesh.F)
    other = gps.gps_histograms(mesh_spectrum(ellipsoid(3, 1.2, 1), 20), params)
    assert np.abs(gps.gps_histograms(mesh_spectrum(scaled, 20), params) - h).sum() < 0.1 * np.abs(other - h).sum()


def test_bending_moves_the_descriptor_less_than_a_change_of_shape():
    """A strip rolled onto a cylinder (an isometry of the surface, up to the chords of its triangles) against the
    flat strip, and against a strip of other proportions."""
    def strip(length, radius=None, nx=61, ny=21):
        x, y = np.meshgrid(np.linspace(0, length, nx), np.linspace(0, 1, ny), indexing="ij")
        idx = np.arange(nx * ny).reshape(nx, ny)
        a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        F = np.vstack([np.c_[a, b, c], np.c_[a, c, d]]).astype(np.int64)
        X, Y = x.ravel(), y.ravel()
        V = np.c_[X, Y, np.zeros_like(X)] if radius is None else \
            np.c_[radius * np.sin(X / radius), Y, radius * (1 - np.cos(X / radius))]
        return Mesh(V, F)

    params = gps.GPSParams(n_pairs=1 << 16)
    flat, bent, other = (gps.gps_histograms(mesh_spectrum(m, 20), params)
                         for m in (strip(3.0), strip(3.0, radius=0.8), strip(1.5)))
    assert np.abs(flat - bent).sum() < 0.2 * np.abs(flat - other).sum()


def test_a_disconnected_spectrum_is_refused():
    spectrum = Spectrum(np.array([0.0, 0.0, 1.0]), np.eye(3), np.ones(3), 3.0)
    with pytest.raises(StageError, match="positive"):
        gps.embedding(spectrum, 2)


def test_the_catalogue_record_reads_the_shared_spectrum():
    method = METHODS["gps"]
    assert method.kind == "vector" and method.chain[-1] == "gps" and {"spectrum": {"k": 40}} in method.chain
