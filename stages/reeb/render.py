"""Drawing a skeleton graph over a matplotlib 3D axis (endpoints in red, the root as a gold star)."""

from __future__ import annotations

import numpy as np


def draw_skeleton(ax, graph, *, endpoints=(), up_order=(0, 1, 2), node_size: float = 6.0) -> None:
    """Draw a skeleton graph (nodes with ``pos``) over a 3D axis; endpoints in red, root as a star.

    ``up_order`` permutes the coordinates the same way :func:`z_up` does for the mesh.
    """
    order = list(up_order)
    pos = {v: np.asarray(d["pos"], dtype=float)[order] for v, d in graph.nodes(data=True)}
    for a, b in graph.edges():
        p, q = pos[a], pos[b]
        ax.plot([p[0], q[0]], [p[1], q[1]], [p[2], q[2]], color="black", lw=1.2, zorder=10)
    inner = np.array([pos[v] for v in graph.nodes if v not in endpoints and v != "root"]).reshape(-1, 3)
    ax.scatter(inner[:, 0], inner[:, 1], inner[:, 2], s=node_size, c="black", depthshade=False, zorder=11)
    if len(endpoints):
        ends = np.array([pos[v] for v in endpoints]).reshape(-1, 3)
        ax.scatter(ends[:, 0], ends[:, 1], ends[:, 2], s=node_size * 5, c="red", depthshade=False, zorder=12)
    if "root" in pos:
        r = pos["root"]
        ax.scatter([r[0]], [r[1]], [r[2]], s=node_size * 12, c="gold", marker="*", edgecolors="black",
                   depthshade=False, zorder=13)
