"""Baseline descriptors: analytic answers on spheres, invariances, discrimination, validation.

Tolerances. D2 and the spherical harmonic descriptor sample the surface at random (seeded):
- D2 with the same seed on a moved copy draws the same point pairs (the face choice depends
  on area ratios only), so its histogram is equal up to pairs that round across a bin edge;
  between seeds it changes by the sampling noise, an L1 of ~0.01 for 2^18 pairs in 64 bins
  (sum over bins of sqrt(p_k / n_pairs)); the tests allow 0.03.
- The SH descriptor moves with its points, but the rotated points fall differently in the
  voxels: a rotated copy differs by the grid anisotropy plus the voxel noise, measured at
  0.6-0.9 % of the descriptor's norm (seed to seed: 1-2 %); the tests allow 3 %.
- ShapeDNA is deterministic: rigid motions and scaling change lambda * A by round-off only.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from topomatch.pipeline.errors import ConfigError, InputError, StageError
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval.baselines import d2, shapedna, spherical_harmonics as sh
from topomatch.stages.retrieval.baselines.sampling import area_centroid_and_rms_radius, sample_surface, triangle_areas


def moved(mesh: Mesh, scale: float = 2.5, seed: int = 1) -> Mesh:
    """``mesh`` rotated by a random rotation, scaled by ``scale`` and translated."""
    R = Rotation.random(random_state=seed).as_matrix()
    return mesh.with_vertices(scale * mesh.V @ R.T + np.array([1.0, -2.0, 3.0]))


@pytest.fixture(scope="module")
def human():
    from topomatch.stages.mesh.io import read_mesh
    from tests_paths import BUNDLED_MESHES

    return read_mesh(BUNDLED_MESHES / "odedstein_human_man.obj.gz")[0]


@pytest.fixture(scope="module")
def torus():
    from topomatch.stages.mesh.io import read_mesh
    from tests_paths import BUNDLED_MESHES

    return read_mesh(BUNDLED_MESHES / "torus.off")[0]


@pytest.fixture(scope="module")
def sphere():
    from shapes import icosphere

    return icosphere(4)  # 2,562 vertices, 5,120 faces, on the unit sphere


# --------------------------------------------------------------------------- sampling


def test_samples_are_uniform_on_a_square():
    # two triangles of areas 3/4 and 1/4 would betray a wrong area weighting; a unit square split
    # off-centre does: points must be uniform on [0, 1]^2
    V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.25, 0, 0]])
    F = np.array([[0, 4, 3], [4, 1, 2], [4, 2, 3]])
    P = sample_surface(V, F, 200_000, np.random.default_rng(0), shuffle=True)
    hist, _, _ = np.histogram2d(P[:, 0], P[:, 1], bins=4, range=[[0, 1], [0, 1]])
    np.testing.assert_allclose(hist / P.shape[0], 1 / 16, atol=0.003)  # 4 sigma of a 1/16 cell count
    np.testing.assert_allclose(P[:, 2], 0.0)


def test_exact_centroid_and_rms_radius(sphere):
    from shapes import unit_cube

    c, rms = area_centroid_and_rms_radius(unit_cube().V, unit_cube().F)
    np.testing.assert_allclose(c, [0.5, 0.5, 0.5], atol=1e-15)
    # faces of the cube [-1/2, 1/2]^3: mean |x|^2 = 1/4 + 2 * 1/12 = 5/12
    assert rms == pytest.approx(np.sqrt(5 / 12), rel=1e-14)
    c, rms = area_centroid_and_rms_radius(sphere.V, sphere.F)
    assert np.abs(c).max() < 1e-12 and rms == pytest.approx(1.0, abs=2e-3)  # flat triangles lie inside


# --------------------------------------------------------------------------- D2


def test_d2_of_a_sphere_matches_the_chord_length_density(sphere):
    # chord length on a sphere of radius R: p(d) = d / (2 R^2) on [0, 2R], mean 4R/3; in units of the
    # mean, p(x) = 8x/9 on [0, 3/2], so bin [a, b) holds 4 (b^2 - a^2) / 9
    params = d2.D2Params()
    hist = d2.descriptor(sphere, params)
    edges = np.clip(np.linspace(0, params.max_distance, params.bins + 1), 0, 1.5)
    expected = np.diff(4 * edges ** 2 / 9)
    assert d2.distance(hist, expected) < 0.03
    assert hist[edges[:-1] >= 1.5 + 1e-9].sum() < 1e-3  # no chord is longer than the diameter
    np.testing.assert_allclose(d2.density(hist, params).sum() * params.max_distance / params.bins, 1.0)


def test_d2_is_a_seeded_probability_vector(torus):
    a = d2.descriptor(torus)
    assert a.shape == (64,) and (a >= 0).all() and a.sum() == pytest.approx(1.0)
    np.testing.assert_array_equal(a, d2.descriptor(torus))
    other = d2.descriptor(torus, d2.D2Params(seed=1))
    assert 0 < d2.distance(a, other) < 0.03  # sampling noise only


def test_d2_invariance_to_rotation_translation_scale(human):
    a = d2.descriptor(human)
    b = d2.descriptor(moved(human))
    # the same seed gives the same pairs; a few may round across a bin edge (2 / n_pairs each)
    assert d2.distance(a, b) <= 20 / d2.D2Params().n_pairs


def test_d2_separates_different_shapes(human, torus):
    noise = d2.distance(d2.descriptor(human), d2.descriptor(moved(human), d2.D2Params(seed=7)))
    between = d2.distance(d2.descriptor(human), d2.descriptor(torus))
    assert noise < 0.03 and between > 10 * noise


def test_d2_overflow_goes_to_the_last_bin(sphere):
    # with the histogram ending at 1 mean distance, the pairs beyond it land in the last bin
    params = d2.D2Params(max_distance=1.0, bins=8)
    hist = d2.descriptor(sphere, params)
    beyond = 1 - 4 * 1.0 ** 2 / 9  # P(x > 1) = 1 - 4/9
    assert hist[-1] == pytest.approx(beyond + 4 * (1 - (7 / 8) ** 2) / 9, abs=0.01)


# --------------------------------------------------------------------------- spherical harmonics


def _band_norms_of(f, params: sh.SphericalHarmonicsParams) -> np.ndarray:
    """Band norms of a function f(x, y, z) on the unit sphere, sampled on the descriptor's grid."""
    theta, _, _ = sh._legendre_table(params.bands, params.n_theta)
    phi = 2 * np.pi * np.arange(params.n_phi) / params.n_phi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    vals = f(np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T))
    return sh.band_norms(vals[None], params)[0]


def test_band_norms_of_known_spherical_functions():
    params = sh.SphericalHarmonicsParams()
    # Y_2^0 = sqrt(5 / 16 pi) (3 z^2 - 1) has unit norm, all of it at l = 2
    y20 = lambda x, y, z: np.sqrt(5 / (16 * np.pi)) * (3 * z ** 2 - 1)  # noqa: E731
    expected = np.zeros(params.bands + 1)
    expected[2] = 1.0
    np.testing.assert_allclose(_band_norms_of(y20, params), expected, atol=1e-12)
    # a constant c: norm c * sqrt(4 pi) at l = 0
    np.testing.assert_allclose(_band_norms_of(lambda x, y, z: 0 * x + 2.0, params)[0], 2 * np.sqrt(4 * np.pi))
    # (a . u)^3 for any unit a: the same norms whatever a (rotation invariance of the band energies)
    rng = np.random.default_rng(0)
    norms = []
    for _ in range(3):
        a = rng.standard_normal(3)
        a /= np.linalg.norm(a)
        norms.append(_band_norms_of(lambda x, y, z: (a[0] * x + a[1] * y + a[2] * z) ** 3, params))
    np.testing.assert_allclose(norms[1], norms[0], atol=1e-12)
    np.testing.assert_allclose(norms[2], norms[0], atol=1e-12)
    assert np.all(norms[0][[0, 2]] < 1e-12) and norms[0][1] > 0 and norms[0][3] > 0  # odd: l = 1 and 3 only


def test_sh_of_a_sphere_has_energy_only_at_l0(sphere):
    x = sh.descriptor(sphere)
    assert x.shape == (32, 17) and (x >= 0).all()
    energy = x ** 2
    assert energy[:, 1:].sum() < 0.01 * energy.sum()  # grid anisotropy + sampling noise (measured 0.13 %)
    # the density sits on the shells around radius 1: r_k = 2 (k + 1/2) / 32 -> k = 15, 16
    assert set(np.argsort(energy[:, 0])[-2:]) == {15, 16}


def test_sh_invariance_to_rotation_translation_scale(human):
    a = sh.descriptor(human)
    b = sh.descriptor(moved(human))
    assert np.linalg.norm(a - b) < 0.03 * np.linalg.norm(a)


def test_sh_separates_different_shapes(human, torus):
    a = sh.descriptor(human)
    rotated = sh.distance(a, sh.descriptor(moved(human, seed=3)))
    between = sh.distance(a, sh.descriptor(torus))
    assert between > 10 * rotated


def test_sh_params_are_validated():
    with pytest.raises(ConfigError, match="n_theta"):
        sh.SphericalHarmonicsParams.parse({"bands": 16, "n_theta": 16}, "stages[0].sh")
    with pytest.raises(ConfigError, match="unknown key"):
        sh.SphericalHarmonicsParams.parse({"L": 8}, "stages[0].sh")


# --------------------------------------------------------------------------- ShapeDNA


def test_shapedna_of_the_unit_sphere(sphere):
    # lambda = l (l + 1) with multiplicity 2l + 1; times the area 4 pi
    x = shapedna.descriptor(sphere, shapedna.ShapeDNAParams(k=24, normalization="area"))
    expected = 4 * np.pi * np.repeat([2, 6, 12, 20], [3, 5, 7, 9])
    np.testing.assert_allclose(x, expected, rtol=0.01)  # linear FEM: +0.02 % (l = 1) to +0.7 % (l = 4)
    default = shapedna.descriptor(sphere, shapedna.ShapeDNAParams(k=24))  # lambda_i * A / i
    np.testing.assert_allclose(default, x / np.arange(1, 25), rtol=1e-9)
    # the multiplicity pattern: within a group the values agree to 1e-6, between groups they jump
    groups = np.split(x, np.cumsum([3, 5, 7])[:])
    for g in groups:
        assert np.ptp(g) < 1e-3 * g.mean()
    assert all(groups[i + 1].min() > 1.5 * groups[i].max() for i in range(3))


def test_shapedna_drops_one_zero_per_component(sphere):
    from shapes import disjoint_union, icosphere

    two = disjoint_union(icosphere(3), icosphere(3), offsets=[(0, 0, 0), (5, 0, 0)])
    raw = shapedna.descriptor(two, shapedna.ShapeDNAParams(k=7, normalization="none"))
    one = shapedna.descriptor(icosphere(3), shapedna.ShapeDNAParams(k=4, normalization="none"))
    # the spectrum of a union is the union of the spectra: 6 x lambda_1, then lambda_4 twice
    np.testing.assert_allclose(raw[:6], one[0], rtol=1e-8)
    np.testing.assert_allclose(raw[6], one[3], rtol=1e-8)


def test_shapedna_invariance_to_rotation_translation_scale(human):
    params = shapedna.ShapeDNAParams(k=20)
    np.testing.assert_allclose(shapedna.descriptor(moved(human), params), shapedna.descriptor(human, params),
                               rtol=1e-7)
    raw = shapedna.ShapeDNAParams(k=20, normalization="none")
    np.testing.assert_allclose(shapedna.descriptor(moved(human, scale=2.0), raw),
                               shapedna.descriptor(human, raw) / 4, rtol=1e-7)  # lambda ~ 1 / length^2


def test_shapedna_normalizations():
    values = np.array([1.0, 2.0, 4.0])
    np.testing.assert_allclose(shapedna.normalize(values, 3.0, "area"), [3, 6, 12])
    np.testing.assert_allclose(shapedna.normalize(values, 3.0, "area_index"), [3, 3, 4])
    np.testing.assert_allclose(shapedna.normalize(values, 3.0, "none"), values)
    with pytest.raises(ValueError, match="normalization"):
        shapedna.normalize(values, 3.0, "max")


def test_shapedna_separates_different_shapes(human, torus):
    params = shapedna.ShapeDNAParams(k=20)
    a = shapedna.descriptor(human, params)
    rotated = shapedna.distance(a, shapedna.descriptor(moved(human), params))
    assert shapedna.distance(a, shapedna.descriptor(torus, params)) > 1e4 * max(rotated, 1e-12)


def test_shapedna_rejects_bad_meshes(shapes):
    tet = shapes.octahedron()
    with pytest.raises(StageError, match="k"):
        shapedna.descriptor(tet, shapedna.ShapeDNAParams(k=6))
    degenerate = Mesh(tet.V, np.vstack([tet.F, [[0, 0, 1]]]), name="bad")
    with pytest.raises(InputError, match="bad"):
        shapedna.descriptor(degenerate)


# --------------------------------------------------------------------------- all baselines


#: Each baseline module and its params type.
BASELINES = {"d2": (d2, d2.D2Params), "spherical_harmonics": (sh, sh.SphericalHarmonicsParams),
             "shapedna": (shapedna, shapedna.ShapeDNAParams)}


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_distance_matrix_matches_distance(name, sphere, torus):
    b, P = BASELINES[name]
    params = P(k=10) if name == "shapedna" else P()
    X = np.stack([b.descriptor(m, params) for m in (sphere, torus)])
    D = b.distance_matrix(X)
    assert D.shape == (2, 2) and np.allclose(np.diag(D), 0) and D[0, 1] == pytest.approx(D[1, 0])
    assert D[0, 1] == pytest.approx(b.distance(X[0], X[1]))
    np.testing.assert_allclose(b.distance_matrix(X[:1], X), D[:1])


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_empty_or_flat_meshes_are_rejected(name):
    empty = Mesh(np.zeros((3, 3)), np.zeros((0, 3)), name="empty")
    b, P = BASELINES[name]
    with pytest.raises(InputError, match="empty"):
        b.descriptor(empty, P())


def test_zero_area_mesh_is_rejected():
    flat = Mesh(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]]), name="line")
    for mod in (d2, sh):
        with pytest.raises(InputError, match="zero area"):
            mod.descriptor(flat)


def test_params_parse_strictly():
    assert d2.D2Params.parse({"bins": 32}, "x").bins == 32
    with pytest.raises(ConfigError, match="bins"):
        d2.D2Params.parse({"bins": "32"}, "stages[1].d2")
    with pytest.raises(ConfigError, match="normalization"):
        shapedna.ShapeDNAParams.parse({"normalization": "max"}, "stages[2].shapedna")
    for _, P in BASELINES.values():
        for field in P.model_fields.values():
            assert field.description


def test_triangle_areas():
    V = np.array([[0.0, 0, 0], [2, 0, 0], [0, 3, 0]])
    np.testing.assert_allclose(triangle_areas(V, np.array([[0, 1, 2]])), [3.0])


def test_shapedna_read_from_the_shared_spectrum_of_the_unit_sphere(sphere):
    from topomatch.pipeline.contract import StageError
    from topomatch.stages.spectral.spectrum import mesh_spectrum

    spectrum = mesh_spectrum(sphere, 30)  # the intrinsic parts' spectrum: lumped (Voronoi) mass
    x = shapedna.from_spectrum(spectrum, 24, normalization="area")
    expected = 4 * np.pi * np.repeat([2, 6, 12, 20], [3, 5, 7, 9])
    np.testing.assert_allclose(x, expected, rtol=0.01)
    np.testing.assert_allclose(shapedna.from_spectrum(spectrum, 24), x / np.arange(1, 25), rtol=1e-12)
    with pytest.raises(StageError, match="raise spectrum.k"):
        shapedna.from_spectrum(spectrum, 31)
