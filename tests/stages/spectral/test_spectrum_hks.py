"""The ``spectrum`` eigenpairs and the heat kernel signature: analytic sphere answers and invariances."""

from __future__ import annotations

import numpy as np
import pytest
from shapes import icosphere

from topomatch.stages.mesh.io import read_mesh
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval.hks import HKSParams, hks_histograms
from topomatch.stages.spectral.heat_kernel import heat_kernel_signature
from topomatch.stages.spectral.spectrum import mesh_spectrum
from tests_paths import BUNDLED_MESHES


@pytest.fixture(scope="module")
def sphere():
    return icosphere(3)  # 642 vertices: solved by ARPACK, not densely


def test_sphere_spectrum_multiplicities_and_orthonormality(sphere):
    s = mesh_spectrum(sphere, 15)
    scaled = s.values * s.area / (4 * np.pi)  # l (l + 1) on the unit sphere
    assert abs(scaled[0]) < 1e-8
    # lumped mass: O(h^2) below the continuum (0.5 % for l = 1 at this size)
    for group, exact in ((slice(1, 4), 2.0), (slice(4, 9), 6.0), (slice(9, 16), 12.0)):
        np.testing.assert_allclose(scaled[group], exact, rtol=3e-2)
        assert np.ptp(scaled[group]) < 1e-2 * exact  # all 2l + 1 copies found (l = 3 splits 3 + 4 by 0.9 %)
    # K-orthonormal with the lumped (diagonal) Voronoi mass
    G = s.vectors.T @ (s.mass[:, None] * s.vectors)
    np.testing.assert_allclose(G, np.eye(16), atol=1e-8)
    assert s.mass.sum() == pytest.approx(s.area)


def test_sphere_hks_is_constant(sphere):
    # every eigenspace of the sphere has sum_m phi_lm(x)^2 = (2l + 1) / (4 pi): h_t is the same at every
    # point, so the mean-normalised log signature is 0 (up to the discretisation)
    s = mesh_spectrum(sphere, 15)
    H = heat_kernel_signature(s, np.geomspace(0.05, 0.5, 4))
    assert np.abs(H).max() < 0.02


def test_hks_invariant_to_rigid_motion_and_scale():
    mesh, _ = read_mesh(BUNDLED_MESHES / "odedstein_spot_low_resolution.obj.gz")
    R = np.linalg.qr(np.random.default_rng(3).standard_normal((3, 3)))[0]
    moved = Mesh(3.7 * mesh.V @ R.T + [1.0, -2.0, 5.0], mesh.F, name="moved")
    params = HKSParams()
    a = heat_kernel_signature(mesh_spectrum(mesh, 30), params.times())
    b = heat_kernel_signature(mesh_spectrum(moved, 30), params.times())
    np.testing.assert_allclose(a, b, atol=1e-6)
    h = hks_histograms(mesh_spectrum(mesh, 30), params)
    assert h.shape == (params.n_times * params.bins,)
    np.testing.assert_allclose(h.reshape(params.n_times, -1).sum(axis=1), 1.0)


def test_spectrum_rejects_too_few_vertices():
    from topomatch.pipeline.errors import StageError

    with pytest.raises(StageError, match="lower spectrum.k"):
        mesh_spectrum(icosphere(0), 20)
