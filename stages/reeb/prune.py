"""Pruning non-salient terminal branches of a Reeb graph, and its endpoints.

The thesis prunes with discrete curve evolution (Bai, Latecki & Liu 2007), a
method for 2D contours. Its 3D counterpart here measures the *visual part* a
branch stands for by the surface area of its band components:

- a **terminal branch** is the chain of nodes from a degree-1 node up to, but
  not including, the first node of degree >= 3 (a junction) or the root;
- its **saliency** is its area divided by the total area of the surface;
- repeatedly, the least salient branch with saliency < ``min_area_fraction`` is
  removed and its area and member vertices are merged into its junction, until
  no such branch is left. Removing a branch can turn its junction into a chain
  node and so lengthen the neighbouring branch, which is then judged anew.

A chain from a leaf to another leaf (the graph of a tube) has no junction and
is never pruned, so the skeleton keeps its extent. Degrees count parallel
edges, so a handle (a cycle) is never mistaken for a branch. **Endpoints** are
the nodes of degree 1 other than the root.
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.reeb.reeb_graph import ROOT, ReebGraph


def endpoints(G: nx.Graph) -> list:
    """Nodes of degree 1, the root excluded, sorted."""
    return sorted((v for v in G.nodes if v != ROOT and G.degree(v) == 1), key=str)


def terminal_branch(G: nx.MultiGraph, leaf) -> tuple[list, object] | None:
    """(branch nodes from ``leaf``, junction) or None when the chain ends at another leaf."""
    branch, prev, node = [leaf], None, leaf
    while True:
        nxt = [u for u in G.neighbors(node) if u != prev]
        if not nxt:
            return None
        step = nxt[0]
        if step == ROOT or G.degree(step) >= 3:
            return branch, step
        if G.degree(step) == 1:
            return None
        branch.append(step)
        prev, node = node, step


def prune_graph(G: nx.MultiGraph, min_area_fraction: float) -> tuple[nx.MultiGraph, int]:
    """Remove terminal branches whose area share is below ``min_area_fraction``.

    Returns the pruned copy and the number of branches removed. Node attributes
    ``area`` and ``members`` of a removed branch are merged into its junction.

    Each leaf's branch and share are kept between removals: a removal changes the degree and the area
    of its junction only, so only the branches that end there (and a junction left as a new leaf) are
    walked again.
    """
    G = G.copy()
    total = sum(d["area"] for _, d in G.nodes(data=True)) or 1.0

    def judged(leaf):
        """(share, branch, junction) of ``leaf``'s terminal branch, or None (a chain to another leaf)."""
        found = terminal_branch(G, leaf)
        if found is None:
            return None
        branch, junction = found
        return sum(G.nodes[v]["area"] for v in branch) / total, branch, junction

    branches = {leaf: judged(leaf) for leaf in endpoints(G)}
    removed = 0
    while True:
        candidates = [(b[0], str(leaf), leaf) for leaf, b in branches.items()
                      if b is not None and b[0] < min_area_fraction]
        if not candidates:
            return G, removed
        leaf = min(candidates, key=lambda c: c[:2])[2]
        _, branch, junction = branches.pop(leaf)
        if junction != ROOT:
            j = G.nodes[junction]
            merged = j["area"] + sum(G.nodes[v]["area"] for v in branch)
            members = np.concatenate([j["members"]] + [G.nodes[v]["members"] for v in branch])
            nx.set_node_attributes(G, {junction: {"area": merged, "members": members}})
        G.remove_nodes_from(branch)
        removed += 1
        again = [other for other, b in branches.items() if b is not None and b[2] == junction]
        if junction in G and junction != ROOT and G.degree(junction) == 1:
            again.append(junction)
        for other in again:
            branches[other] = judged(other)


def cycle_rank(G: nx.MultiGraph) -> int:
    """E - V + C of the graph without the root node."""
    H = G.subgraph([v for v in G.nodes if v != ROOT])
    return H.number_of_edges() - H.number_of_nodes() + (nx.number_connected_components(H) if len(H) else 0)


class PruneParams(Params):
    """Parameters of the ``prune`` stage."""

    min_area_fraction: float = Field(0.01, ge=0, lt=1, description="remove terminal branches whose surface "
                                     "area share is below this (0 keeps every branch)")


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A pruned Reeb graph with its endpoints.

    Attributes
    ----------
    graph : networkx.MultiGraph
        Same attributes as :class:`~topomatch.stages.reeb.reeb_graph.ReebGraph`.
    endpoints : list
        Degree-1 nodes (root excluded).
    removed_branches : int
    cycle_rank : int
        Of the pruned graph, root excluded.
    """

    graph: nx.MultiGraph
    endpoints: list
    removed_branches: int
    cycle_rank: int

    def summary(self) -> dict:
        return {"nodes": self.graph.number_of_nodes(), "edges": self.graph.number_of_edges(),
                "endpoints": len(self.endpoints), "removed_branches": self.removed_branches,
                "cycle_rank": self.cycle_rank}


def make_skeleton(reeb: ReebGraph, min_area_fraction: float) -> Skeleton:
    """Prune ``reeb`` and collect its endpoints."""
    G, removed = prune_graph(reeb.graph, min_area_fraction)
    return Skeleton(G, endpoints(G), removed, cycle_rank(G))


@dataclass(frozen=True, eq=False)
class PruneResult(StageResult):
    skeleton: Skeleton

    def summary(self) -> dict:
        return self.skeleton.summary()


@stage("prune", params=PruneParams, version=1, consumes=("reeb",), produces=("skeleton",))
def prune(reeb: ReebGraph, *, params: PruneParams) -> PruneResult:
    """Remove non-salient terminal branches (area share below a threshold); endpoints = degree-1 nodes."""
    return PruneResult(make_skeleton(reeb, params.min_area_fraction))
