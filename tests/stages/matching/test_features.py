"""Endpoint features: hand-computed values on a small graph; invariance on real skeletons."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from topomatch.stages.matching.features import endpoint_features, skeleton_root
from topomatch.stages.morse.mixture import mixture_distance
from topomatch.stages.reeb.level_sets import level_values
from topomatch.stages.reeb.prune import make_skeleton
from topomatch.stages.reeb.reeb_graph import ROOT, reeb_graph


def _star():
    """root -- 0 (junction) with leaves 1, 2, 3 at lengths 1, 2, 3; a parallel longer edge 0-3."""
    G = nx.MultiGraph()
    areas = {ROOT: 0.0, 0: 4.0, 1: 1.0, 2: 2.0, 3: 3.0}
    for v, a in areas.items():
        G.add_node(v, area=a, pos=np.zeros(3))
    G.add_edge(ROOT, 0, length=1.0)
    G.add_edge(0, 1, length=1.0)
    G.add_edge(0, 2, length=2.0)
    G.add_edge(0, 3, length=3.0)
    return G


def test_hand_computed_features():
    f = endpoint_features(_star())
    assert f.endpoints == [1, 2, 3] and f.root == ROOT
    dc = np.array([2.0, 3.0, 4.0])      # root -> 0 -> leaf
    s = dc.sum()
    pair = np.array([[0, 3, 4], [3, 0, 5], [4, 5, 0]], float)
    np.testing.assert_allclose(f.features[:, 0], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(f.features[:, 1], pair.sum(1) / s)
    np.testing.assert_allclose(f.features[:, 2], dc / s)


def test_parallel_edges_use_the_shortest():
    G = _star()
    G.add_edge(0, 3, length=10.0)
    G.add_edge(0, 4, length=1.0)
    G.add_node(4, area=0.0, pos=np.zeros(3))
    f = endpoint_features(G)
    assert 3 not in f.endpoints  # node 3 now has degree 2 (a loop), not an endpoint
    assert f.endpoints == [1, 2, 4]


def test_root_without_root_node_is_nearest_to_area_centroid():
    G = nx.MultiGraph()
    for v, (x, a) in enumerate([(0.0, 1.0), (1.0, 1.0), (2.0, 1.0), (10.0, 0.0)]):
        G.add_node(v, pos=np.array([x, 0, 0]), area=a)
    G.add_edges_from([(0, 1), (1, 2), (2, 3)], length=1.0)
    assert skeleton_root(G) == 1


@pytest.mark.parametrize("function", ["mixture", "fiedler"])
@pytest.mark.parametrize("name", ["odedstein_hand_closed.obj.gz", "odedstein_cat-low-resolution.obj.gz"])
def test_features_invariant_to_similarity(bundled_mesh, name, function):
    from topomatch.stages.mesh.mesh import Mesh
    from topomatch.stages.morse.fiedler import fiedler_function

    m = bundled_mesh(name)
    R = Rotation.from_rotvec([0.3, -1.1, 0.4]).as_matrix()

    def feats(V):
        mf = mixture_distance(V, m.F) if function == "mixture" else fiedler_function(Mesh(V, m.F))
        S = make_skeleton(reeb_graph(V, m.F, mf.values, level_values(mf.values, 22), root=mf.root), 0.01)
        return endpoint_features(S.graph).features

    a, b = feats(m.V), feats(3.0 * m.V @ R.T + [1.0, 2.0, -5.0])
    assert a.shape == b.shape and len(a) >= 3
    np.testing.assert_allclose(b, a, atol=1e-9)
