"""Gaussian vertex noise: seeded, with the stated standard deviation in the stated unit."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.errors import ConfigError
from topomatch.stages.mesh.measures import bbox_diagonal, mean_edge_length
from topomatch.stages.mesh.noise import NoiseParams, noise


def test_same_seed_same_mesh_other_seed_other_mesh(bundled_mesh):
    mesh = bundled_mesh("torus.off")
    a = noise(mesh, params=NoiseParams(sigma=0.01, seed=7))
    b = noise(mesh, params=NoiseParams(sigma=0.01, seed=7))
    c = noise(mesh, params=NoiseParams(sigma=0.01, seed=8))
    np.testing.assert_array_equal(a.mesh.V, b.mesh.V)
    assert not np.allclose(a.mesh.V, c.mesh.V)
    np.testing.assert_array_equal(a.mesh.F, mesh.F)
    assert a.mesh.name == mesh.name


def test_displacement_statistics_match_sigma(bundled_mesh):
    mesh = bundled_mesh("odedstein_cat-low-resolution.obj.gz")  # 7949 vertices: N = 23847 coordinates
    result = noise(mesh, params=NoiseParams(sigma=0.002, relative_to="bbox_diagonal", seed=11))
    sigma = result.sigma_absolute
    D = (result.mesh.V - mesh.V).ravel()
    n = D.size
    # sample std of N normals: relative standard error 1/sqrt(2N) = 0.46%; allow 4 standard errors
    assert np.std(D) == pytest.approx(sigma, rel=4 / np.sqrt(2 * n))
    assert abs(D.mean()) < 4 * sigma / np.sqrt(n)
    # |d|^2 / sigma^2 is chi-square with 3 dof per vertex: rms = sqrt(3) sigma
    assert result.rms_displacement == pytest.approx(np.sqrt(3) * sigma, rel=4 / np.sqrt(2 * n))


@pytest.mark.parametrize("relative_to", ["mean_edge", "bbox_diagonal", "absolute"])
def test_sigma_unit(bundled_mesh, relative_to):
    mesh = bundled_mesh("eight_genus2.off")
    unit = {"mean_edge": mean_edge_length(mesh), "bbox_diagonal": bbox_diagonal(mesh.V), "absolute": 1.0}[relative_to]
    result = noise(mesh, params=NoiseParams(sigma=0.25, relative_to=relative_to))
    assert result.sigma_absolute == pytest.approx(0.25 * unit, rel=1e-12)


def test_mean_edge_length_of_the_cube(shapes):
    # 12 unit edges and 6 face diagonals of length sqrt(2)
    assert mean_edge_length(shapes.unit_cube()) == pytest.approx((12 + 6 * np.sqrt(2)) / 18)


def test_zero_sigma_is_the_identity(shapes):
    octa = shapes.octahedron()
    result = noise(octa, params=NoiseParams(sigma=0.0, seed=3))
    np.testing.assert_array_equal(result.mesh.V, octa.V)
    assert result.rms_displacement == 0.0


@pytest.mark.parametrize("bad", [{"sigma": -0.1}, {"sigma": "0.1"}, {"relative_to": "edge"}, {"seed": 1.5},
                                 {"seed": -1}])
def test_invalid_params(bad):
    with pytest.raises(ConfigError, match=r"^stages\[1\].noise\."):
        NoiseParams.parse(bad, "stages[1].noise")
