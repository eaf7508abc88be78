"""Pruning: small terminal branches go, areas and members are conserved, chains and cycles stay."""

from __future__ import annotations

import networkx as nx
import numpy as np

from topomatch.stages.reeb.prune import cycle_rank, endpoints, prune_graph


def _graph(edges, areas):
    G = nx.MultiGraph()
    for v, a in areas.items():
        G.add_node(v, area=a, members=np.array([v]), pos=np.zeros(3), band=0, value=0.0)
    G.add_edges_from(edges)
    return G


def test_small_branch_removed_and_merged():
    # a long chain 0-1-2-3-4 with a tiny branch 5 on node 2 and a big branch 6-7 on node 2
    G = _graph([(0, 1), (1, 2), (2, 3), (3, 4), (2, 5), (2, 6), (6, 7)],
               {0: 10, 1: 10, 2: 10, 3: 10, 4: 10, 5: 0.5, 6: 10, 7: 10})
    P, removed = prune_graph(G, 0.01)
    assert removed == 1 and 5 not in P and set(endpoints(P)) == {0, 4, 7}
    assert P.nodes[2]["area"] == 10.5 and sorted(P.nodes[2]["members"]) == [2, 5]
    assert sum(d["area"] for _, d in P.nodes(data=True)) == sum(d["area"] for _, d in G.nodes(data=True))


def test_chain_is_never_pruned():
    G = _graph([(0, 1), (1, 2)], {0: 0.001, 1: 1.0, 2: 0.001})
    P, removed = prune_graph(G, 0.5)
    assert removed == 0 and P.number_of_nodes() == 3


def test_cycles_survive_pruning():
    # a loop 0-1-2-3-0 (a handle) with tails; the handle nodes have degree 2 or more
    G = _graph([(0, 1), (1, 2), (2, 3), (3, 0), (0, 4), (2, 5), (5, 6)],
               {0: 1, 1: 1, 2: 1, 3: 1, 4: 0.01, 5: 1, 6: 1})
    P, removed = prune_graph(G, 0.05)
    assert cycle_rank(P) == 1 and 4 not in P and 6 in P and removed == 1


def test_iterated_pruning_rejudges_lengthened_branches():
    # junction 1 has two tiny leaves (2, 3); after both go, 1 becomes a leaf-chain end, not pruned
    G = _graph([(0, 1), (1, 2), (1, 3)], {0: 1.0, 1: 1.0, 2: 0.001, 3: 0.002})
    P, removed = prune_graph(G, 0.01)
    assert removed == 1  # after removing 2, node 1 has degree 2: 3 is the end of the chain 0-1-3
    assert set(P.nodes) == {0, 1, 3}
