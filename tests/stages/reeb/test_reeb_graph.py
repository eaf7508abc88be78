"""Reeb graph truths: cycle rank = genus, exact areas and centroids, members, invariance."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from topomatch.stages.morse.height import principal_height
from topomatch.stages.morse.mixture import mixture_distance
from topomatch.stages.morse.fiedler import fiedler_function
from topomatch.stages.reeb.level_sets import band_index, level_values
from topomatch.stages.reeb.prune import make_skeleton
from topomatch.stages.reeb.reeb_graph import ROOT, reeb_graph

FUNCTIONS = {
    "mixture": lambda m: mixture_distance(m.V, m.F),
    "fiedler": lambda m: fiedler_function(m),
    "height": lambda m: principal_height(m.V),
}


def _graph(m, kind, n, split=True):
    mf = FUNCTIONS[kind](m)
    return mf, reeb_graph(m.V, m.F, mf.values, level_values(mf.values, n), root=mf.root, split_handle_bands=split)


GENUS = [("torus.off", 1), ("eight_genus2.off", 2), ("odedstein_spot_low_resolution.obj.gz", 0)]


@pytest.mark.parametrize("kind", sorted(FUNCTIONS))
@pytest.mark.parametrize("name,genus", GENUS)
def test_cycle_rank_equals_genus_for_every_n(bundled_mesh, name, genus, kind):
    m = bundled_mesh(name)
    for n in list(range(4, 31)) + [40, 60, 100, 200]:
        _, R = _graph(m, kind, n)
        assert R.cycle_rank == genus, n
        assert nx.number_connected_components(R.graph) == 1
        assert len(R.levels) - 1 >= n


@pytest.mark.parametrize("kind", sorted(FUNCTIONS))
@pytest.mark.parametrize("name,genus", GENUS)
def test_uniform_bands_never_invent_cycles(bundled_mesh, name, genus, kind):
    """Without band splitting the graph is a quotient of the Reeb graph: a band can swallow a whole
    handle (the mixture distance of the genus-2 'eight' has 12 saddles between 0.39 and 0.94 and
    needs N >= 29 uniform bands), but the cycle rank never exceeds the genus."""
    m = bundled_mesh(name)
    ranks = []
    for n in range(4, 31):
        _, R = _graph(m, kind, n, split=False)
        assert R.cycle_rank <= genus and len(R.levels) - 1 == n
        ranks.append(R.cycle_rank)
    assert ranks[-1] == genus


def test_noise_hides_handles_only_without_splitting(bundled_mesh):
    m = bundled_mesh("eight_genus2.off")
    V = m.V + np.random.default_rng(11).normal(size=m.V.shape) * 0.004 * np.linalg.norm(np.ptp(m.V, axis=0))
    f = mixture_distance(V, m.F).values
    uniform = reeb_graph(V, m.F, f, level_values(f, 22), split_handle_bands=False)
    split = reeb_graph(V, m.F, f, level_values(f, 22))
    assert uniform.cycle_rank < 2 and split.cycle_rank == 2


@pytest.mark.parametrize("level", [2, 3])
def test_sphere_is_a_tree(shapes, level):
    m = shapes.icosphere(level)
    m = type(m)(m.V * [1.0, 1.3, 2.0], m.F)  # an ellipsoid: a Morse height function
    for kind in FUNCTIONS:
        _, R = _graph(m, kind, 22)
        assert R.cycle_rank == 0


def test_node_measures_are_exact(bundled_mesh):
    m = bundled_mesh("eight_genus2.off")
    mf, R = _graph(m, "mixture", 22)
    P = m.V[m.F]
    tri_area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    nodes = [d for v, d in R.graph.nodes(data=True) if v != ROOT]
    area = np.array([d["area"] for d in nodes])
    pos = np.array([d["pos"] for d in nodes])
    value = np.array([d["value"] for d in nodes])
    assert area.sum() == pytest.approx(tri_area.sum(), rel=1e-12)
    centroid = (tri_area[:, None] * P.mean(1)).sum(0) / tri_area.sum()
    np.testing.assert_allclose((area[:, None] * pos).sum(0) / area.sum(), centroid, atol=1e-12)
    integral = (tri_area * mf.values[m.F].mean(1)).sum()
    assert (area * value).sum() == pytest.approx(integral, rel=1e-12)


def test_members_partition_the_vertices_by_band(bundled_mesh):
    m = bundled_mesh("odedstein_hand_lowres.obj.gz")  # open at the wrist
    mf, R = _graph(m, "height", 22)
    bands = band_index(mf.values, R.levels)
    seen = np.concatenate([d["members"] for v, d in R.graph.nodes(data=True) if v != ROOT])
    assert np.array_equal(np.sort(seen), np.arange(m.n_vertices))
    for v, d in R.graph.nodes(data=True):
        if v != ROOT:
            assert np.all(bands[d["members"]] == d["band"])
    for a, b, d in R.graph.edges(data=True):
        if ROOT not in (a, b):
            assert abs(R.graph.nodes[a]["band"] - R.graph.nodes[b]["band"]) == 1
            assert {R.graph.nodes[a]["band"], R.graph.nodes[b]["band"]} == {d["level"] - 1, d["level"]}


def test_root_modes(bundled_mesh):
    m = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    mf = FUNCTIONS["mixture"](m)
    levels = level_values(mf.values, 22)
    first = reeb_graph(m.V, m.F, mf.values, levels, root=mf.root, root_mode="first_band").graph
    nearest = reeb_graph(m.V, m.F, mf.values, levels, root=mf.root, root_mode="nearest").graph
    none = reeb_graph(m.V, m.F, mf.values, levels, root=mf.root, root_mode="none").graph
    band0 = [v for v, d in first.nodes(data=True) if d["band"] == 0]
    assert first.degree(ROOT) == len(band0) and nearest.degree(ROOT) == 1 and ROOT not in none


def test_tube_gives_a_path():
    import igl

    # an open cylinder along z: 40 rings of 24 vertices
    theta = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    z = np.linspace(0, 10, 40)
    V = np.array([[np.cos(t), np.sin(t), h] for h in z for t in theta])
    F = []
    for i in range(39):
        for j in range(24):
            a, b = i * 24 + j, i * 24 + (j + 1) % 24
            F += [[a, b, b + 24], [a, b + 24, a + 24]]
    F = np.array(F)
    f = V[:, 2].copy()
    R = reeb_graph(V, F, f, level_values(f, 10))
    G = R.graph
    assert G.number_of_nodes() == 10 and G.number_of_edges() == 9
    assert sorted(d for _, d in G.degree()) == [1, 1] + [2] * 8
    assert igl.boundary_loop_all(F) and R.cycle_rank == 0


def _skeleton_signature(m, kind):
    mf, R = _graph(m, kind, 22)
    S = make_skeleton(R, 0.01)
    total = sum(d["area"] for _, d in S.graph.nodes(data=True))
    return S, total


@pytest.mark.parametrize("kind", sorted(FUNCTIONS))
def test_similarity_transform_gives_an_isomorphic_skeleton(bundled_mesh, kind):
    m = bundled_mesh("odedstein_cat-low-resolution.obj.gz")
    rng = np.random.default_rng(5)
    R = Rotation.random(random_state=rng).as_matrix()
    V2 = 2.0 * m.V @ R.T + [3.0, -1.0, 7.0]
    S1, t1 = _skeleton_signature(m, kind)
    S2, t2 = _skeleton_signature(type(m)(V2, m.F), kind)
    match = nx.algorithms.isomorphism.MultiGraphMatcher(
        S1.graph, S2.graph, node_match=lambda a, b: a["band"] == b["band"]
        and abs(a["area"] / t1 - b["area"] / t2) < 1e-9)
    assert match.is_isomorphic()
    assert len(S1.endpoints) == len(S2.endpoints)
    mapping = match.mapping
    for v in S1.graph.nodes:
        p1 = np.asarray(S1.graph.nodes[v]["pos"])
        p2 = np.asarray(S2.graph.nodes[mapping[v]]["pos"])
        np.testing.assert_allclose(p2, 2.0 * R @ p1 + [3.0, -1.0, 7.0], atol=1e-9)


@pytest.mark.parametrize("rounds", [0, 1, 8])
def test_row_components_number_like_scipy(monkeypatch, rounds):
    """The min-hooking components of the band partition equal scipy's, labels included, also when
    the hooking rounds run out and scipy finishes the job."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    import topomatch.stages.reeb.reeb_graph as rg

    monkeypatch.setattr(rg, "HOOK_ROUNDS", rounds)
    rng = np.random.default_rng(3)
    for _ in range(100):
        n, r, e = int(rng.integers(1, 300)), int(rng.integers(0, 200)), int(rng.integers(0, 40))
        rows = rng.integers(0, n, size=(3, r)).astype(np.int32)
        a, b = rng.integers(0, n, size=(2, e)).astype(np.int32)
        u, w = np.concatenate([rows[0], rows[0], a]), np.concatenate([rows[1], rows[2], b])
        expected = connected_components(coo_matrix((np.ones(len(u)), (u, w)), shape=(n, n)), directed=False)[1]
        assert np.array_equal(rg._row_components(n, rows, a, b), expected)
