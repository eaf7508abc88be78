"""Drawing a skeleton inside its surface with correct depth (headless matplotlib, no OpenGL).

matplotlib's 3D axes sort each collection as a whole, so a skeleton drawn as its own collection
shows every branch over the surface, even a branch behind a leg. Here the scene is projected
orthographically (the view of ``elev``/``azim``, as in matplotlib) and drawn by the painter's
algorithm in one 2D collection: the surface's triangles (translucent, shaded, coloured by the Morse
function), the iso-curves, the skeleton's edges (cut into short pieces, each a thin quad) and the
endpoint and root markers, all sorted far to near. A branch inside the body shows through the one
translucent layer in front of it; a branch behind another part of the body is covered by that
part's surface as well, so it looks fainter, as it should.
"""

from __future__ import annotations

import numpy as np

#: Colours and markers of the skeleton drawings (also named in the legends).
SKELETON_STYLE = {"edge": "black", "endpoint": "red", "root": "gold", "isoline": "0.25"}


def view_basis(elev: float, azim: float) -> np.ndarray:
    """(3, 3) rows: screen right, screen up, towards the viewer, for matplotlib's ``elev``/``azim`` (degrees)."""
    e, a = np.radians(elev), np.radians(azim)
    toward = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    right = np.array([-np.sin(a), np.cos(a), 0.0])
    up = np.cross(toward, right)
    return np.vstack([right, up, toward])


def _quads(P2: np.ndarray, Q2: np.ndarray, half_width: float) -> np.ndarray:
    """Thin screen-space quads (k, 4, 2) along the segments P2 -> Q2 (k, 2)."""
    d = Q2 - P2
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    n *= half_width
    return np.stack([P2 - n, P2 + n, Q2 + n, Q2 - n], axis=1)


def _discs(C2: np.ndarray, radius: float, sides: int = 12) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    return C2[:, None, :] + radius * np.stack([np.cos(t), np.sin(t)], axis=1)[None]


def _star(c: np.ndarray, radius: float) -> np.ndarray:
    t = np.pi / 2 + np.arange(10) * np.pi / 5
    r = np.where(np.arange(10) % 2 == 0, radius, radius * 0.45)
    return c[None, :] + np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


def draw_scene(ax, V: np.ndarray, F: np.ndarray, *, values: np.ndarray | None = None, cmap: str = "coolwarm",
               isolines: np.ndarray | None = None, graph=None, endpoints=(), elev: float = 15.0,
               azim: float = -60.0, alpha: float = 0.45, line_width: float = 0.006, pieces: int = 6,
               faded: np.ndarray | None = None, paths: list | None = None) -> None:
    """Draw a surface with its skeleton on a 2D axis, depth-sorted (see the module's doc).

    Parameters
    ----------
    V, F : (n, 3) float, (m, 3) int
        The surface, already in display orientation (z up).
    values : (n,) float, optional
        The Morse function; colours the surface through ``cmap`` from its minimum (0) to maximum (1).
    isolines : (k, 2, 3) float, optional
        Iso-curve segments.
    graph : networkx graph, optional
        Nodes with ``pos`` (3,), in the same orientation as ``V``; ``"root"`` drawn as a gold star.
    endpoints : nodes drawn as red discs.
    line_width : skeleton width as a fraction of the view's extent.
    pieces : each skeleton edge is cut into this many pieces for the depth sort.
    faded : (m,) bool, optional
        Faces drawn in light grey instead of their colour (e.g. bands not reached yet).
    paths : list of (nodes, rgba), optional
        Paths through ``graph`` drawn thicker in their colour (e.g. shortest paths).
    """
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Polygon

    from topomatch.stages.mesh.render import face_colors

    B = view_basis(elev, azim)
    S = np.asarray(V, float) @ B.T  # screen x, screen y, depth (larger: nearer)
    extent = float(np.ptp(S[:, :2], axis=0).max()) or 1.0
    SF = S[F]  # (m, 3, 3) the faces' corners on the screen
    polys, colors, depth = [SF[:, :, :2]], [], [SF[:, :, 2].mean(axis=1)]
    rgb = face_colors(V, F, values=values, cmap=cmap)
    if faded is not None:
        rgb = np.where(np.asarray(faded, bool)[:, None], 0.55 + 0.4 * rgb.mean(axis=1, keepdims=True), rgb)
    colors.append(np.column_stack([rgb, np.full(len(F), alpha)]))
    if isolines is not None and len(isolines):
        seg = np.asarray(isolines, float) @ B.T
        polys.append(_quads(seg[:, 0, :2], seg[:, 1, :2], 0.0015 * extent))
        depth.append(seg[:, :, 2].mean(axis=1) + 1e-6 * extent)  # on the surface: just in front of it
        colors.append(np.tile([0.25, 0.25, 0.25, 0.7], (len(seg), 1)))
    if graph is not None:
        pos = {n: np.asarray(d["pos"], float) @ B.T for n, d in graph.nodes(data=True)}
        t = np.linspace(0.0, 1.0, pieces + 1)[:, None]
        for a, b in graph.edges():
            pts = pos[a] + t * (pos[b] - pos[a])
            polys.append(_quads(pts[:-1, :2], pts[1:, :2], line_width * extent / 2))
            depth.append((pts[:-1, 2] + pts[1:, 2]) / 2)
            colors.append(np.tile([0, 0, 0, 1.0], (pieces, 1)))
        for nodes, rgba in paths or ():
            for a, b in zip(nodes[:-1], nodes[1:]):
                pts = pos[a] + t * (pos[b] - pos[a])
                polys.append(_quads(pts[:-1, :2], pts[1:, :2], 1.4 * line_width * extent))
                depth.append((pts[:-1, 2] + pts[1:, 2]) / 2 + 2e-6 * extent)  # over the plain edge
                colors.append(np.tile(rgba, (pieces, 1)))
        inner = [n for n in graph.nodes if n not in endpoints and n != "root"]
        for nodes, radius, rgba in ((inner, 1.2, (0, 0, 0, 1)), (list(endpoints), 2.6, (0.9, 0, 0, 1))):
            if nodes:
                C = np.array([pos[n] for n in nodes])
                polys.append(_discs(C[:, :2], radius * line_width * extent))
                depth.append(C[:, 2] + 1e-6 * extent)
                colors.append(np.tile(rgba, (len(nodes), 1)))
    flat = [p for group in polys for p in group]
    order = np.argsort(np.concatenate(depth), kind="stable")
    rgba = np.vstack(colors)[order]
    ax.add_collection(PolyCollection([flat[i] for i in order], facecolors=rgba, edgecolors="none", linewidths=0))
    if graph is not None and "root" in pos:  # the root on top: it marks where the graph is rooted
        r = pos["root"]
        ax.add_patch(Polygon(_star(r[:2], 4.5 * line_width * extent), closed=True, facecolor="gold",
                             edgecolor="black", lw=0.6, zorder=5))
    lo, hi = S[:, :2].min(axis=0), S[:, :2].max(axis=0)
    mid, half = (lo + hi) / 2, (hi - lo).max() / 2 * 1.05 or 1.0
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_aspect("equal")
    ax.set_axis_off()


def skeleton_legend_handles(*, isolines: bool = True, root: bool = True) -> list:
    """Legend handles for the skeleton drawings: edges, endpoints (red), root (gold star), iso-curves."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="black", lw=1.5, label="skeleton edge"),
               Line2D([], [], color="red", marker="o", ls="none", ms=6, label="endpoint (degree 1)")]
    if root:
        handles.append(Line2D([], [], color="gold", marker="*", markeredgecolor="black", ls="none", ms=11,
                              label="root (centroid of a rooted function)"))
    if isolines:
        handles.append(Line2D([], [], color="0.25", lw=0.8, label="iso-curve (level-set boundary)"))
    return handles
