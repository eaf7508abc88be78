"""SD-GDM (spectrum of the geodesic distance matrix): analytic geodesics, invariances, discrimination.

Tolerances. The heat method (time step h^2) smooths the distance near the source and the boundary:
measured 1.6 % mean / 1.9 % largest relative error on the flat grid below, 0.8 % / 1.0 % on a
2,562-vertex icosphere; the tests allow 3 %. The descriptor is deterministic: a rigid motion or a
uniform scale changes it by round-off (the farthest-point choice breaks near-ties by index).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from topomatch.pipeline.errors import InputError, StageError
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval.baselines import sdgdm
from topomatch.stages.retrieval.catalogue import METHODS


def strip(nx: int = 41, ny: int = 21, radius: float | None = None) -> Mesh:
    """A 2 x 1 grid of triangles, flat, or rolled along x onto a cylinder of ``radius`` (an exact isometry)."""
    x, y = np.meshgrid(np.linspace(0, 2, nx), np.linspace(0, 1, ny), indexing="ij")
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.vstack([np.c_[a, b, c], np.c_[a, c, d]]).astype(np.int64)
    X, Y = x.ravel(), y.ravel()
    if radius is None:
        V = np.c_[X, Y, np.zeros_like(X)]
    else:
        V = np.c_[radius * np.sin(X / radius), Y, radius * (1 - np.cos(X / radius))]
    return Mesh(V, F, name="strip" if radius is None else "bent strip")


@pytest.fixture(scope="module")
def sphere():
    from shapes import icosphere

    return icosphere(4)


@pytest.fixture(scope="module")
def human():
    from topomatch.stages.mesh.io import read_mesh
    from tests_paths import BUNDLED_MESHES

    return read_mesh(BUNDLED_MESHES / "odedstein_human_man.obj.gz")[0]


def test_geodesics_on_a_flat_grid_are_euclidean():
    mesh = strip()
    samples, G = sdgdm.geodesic_distance_matrix(mesh, 40)
    E = np.linalg.norm(mesh.V[samples][:, None] - mesh.V[samples][None], axis=2)
    assert G.shape == (40, 40) and np.allclose(G, G.T) and np.all(np.diag(G) == 0)
    assert np.abs(G - E).max() <= 0.03 * E.max()
    # farthest-point sampling starts at a corner of the rectangle and spreads: the samples cover it
    assert E.max() == pytest.approx(np.hypot(2, 1), rel=1e-9)


def test_geodesics_on_a_sphere_are_great_circles(sphere):
    samples, G = sdgdm.geodesic_distance_matrix(sphere, 40)
    P = sphere.V[samples]
    A = np.arccos(np.clip(P @ P.T, -1.0, 1.0))
    assert np.abs(G - A).max() <= 0.03 * np.pi


def test_spectrum_of_a_known_matrix():
    # the distance matrix of two points: eigenvalues +-d; of a 3-point equilateral: 2d, -d, -d
    assert sdgdm.spectrum(np.array([[0.0, 3.0], [3.0, 0.0]]), 2) == pytest.approx([1.0])
    tri = np.ones((3, 3)) - np.eye(3)
    assert sdgdm.spectrum(tri, 3) == pytest.approx([0.5, 0.5])
    assert sdgdm.spectrum(tri, 5) == pytest.approx([0.5, 0.5, 0.0, 0.0])  # zero-padded past p
    assert sdgdm.spectrum(tri, 4, log=True) == pytest.approx([np.log(0.5), np.log(0.5), np.log(sdgdm.LOG_FLOOR)])


def test_invariance_to_rigid_motion_and_scale(human):
    params = sdgdm.SDGDMParams(n_points=64)
    a = sdgdm.descriptor(human, params)
    R = Rotation.random(random_state=3).as_matrix()
    b = sdgdm.descriptor(human.with_vertices(2.5 * human.V @ R.T + np.array([1.0, -2.0, 3.0])), params)
    assert a.shape == (params.k - 1,)
    assert np.abs(a - b).max() <= 1e-6


def test_nearly_invariant_to_bending(sphere):
    # rolling a flat strip onto a cylinder keeps every length: the descriptor must not move, while a
    # different shape is far
    params = sdgdm.SDGDMParams(n_points=64)
    flat, bent = sdgdm.descriptor(strip(), params), sdgdm.descriptor(strip(radius=0.7), params)
    other = sdgdm.descriptor(sphere, params)
    assert sdgdm.distance(flat, bent) <= 0.01 * sdgdm.distance(flat, other)


def test_separates_different_shapes(human, sphere):
    params = sdgdm.SDGDMParams(n_points=64)
    a, b = sdgdm.descriptor(human, params), sdgdm.descriptor(sphere, params)
    assert sdgdm.distance(a, b) > 0.05


def test_distance_matrix_matches_distance():
    X = np.random.default_rng(0).random((4, 7))
    D = sdgdm.distance_matrix(X)
    assert D[1, 3] == pytest.approx(sdgdm.distance(X[1], X[3]))
    with pytest.raises(ValueError):
        sdgdm.distance(X[0], X[1, :3])


def test_edge_graph_fallback_when_the_heat_method_fails(monkeypatch):
    # a mesh whose heat-method factorisation fails gets Dijkstra distances along its edges: above the geodesic,
    # by at most sqrt 2 on this grid of right triangles (across the diagonals), exact along the axes
    mesh = strip()
    monkeypatch.setattr(sdgdm, "_heat_solver", lambda V, F: None)
    samples, G = sdgdm.geodesic_distance_matrix(mesh, 40)
    E = np.linalg.norm(mesh.V[samples][:, None] - mesh.V[samples][None], axis=2)
    assert np.all(G >= E - 1e-9) and np.all(G <= np.sqrt(2) * E + 1e-9)


def test_bad_meshes_are_rejected(sphere):
    with pytest.raises(InputError):
        sdgdm.descriptor(Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), name="empty"))
    from shapes import disjoint_union

    with pytest.raises(StageError, match="components"):
        sdgdm.descriptor(disjoint_union(sphere, sphere))


def test_catalogue_record_is_a_vector_method_outside_the_default_fusion():
    m = METHODS["sdgdm"]
    assert m.kind == "vector" and m.chain[-1] == "sdgdm" and m.distance is sdgdm.distance_matrix
    assert "sdgdm" not in METHODS["topomatch"].parts
