"""Drawing triangle meshes with matplotlib (headless, no OpenGL needed): shading, up axis, a shaded mesh."""

from __future__ import annotations

import numpy as np

from topomatch.stages.mesh.mesh import Mesh


def face_shading(V: np.ndarray, F: np.ndarray, light: tuple[float, float, float] = (0.4, -0.5, 0.8)) -> np.ndarray:
    """Lambert shading in [0.25, 1] per face, (m,) float, from a directional light."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    l = np.asarray(light, dtype=float)
    l /= np.linalg.norm(l)
    return 0.25 + 0.75 * np.abs(n @ l)


#: Coordinate permutations that put a mesh's up axis along matplotlib's +z.
UP_ORDER = {"x": (1, 2, 0), "y": (2, 0, 1), "z": (0, 1, 2)}


def z_up(mesh: Mesh, up: str) -> Mesh:
    """A copy of ``mesh`` with its ``up`` axis ('x', 'y' or 'z') along +z (a cyclic permutation, for display)."""
    return Mesh(mesh.V[:, list(UP_ORDER[up])], mesh.F, mesh.name)


def face_colors(V: np.ndarray, F: np.ndarray, *, values: np.ndarray | None = None, cmap: str = "viridis",
                color=(0.75, 0.78, 0.85)) -> np.ndarray:
    """Shaded face colours (m, 3): ``values`` (n,) through ``cmap`` from its minimum to its maximum
    (face means), or the plain ``color``, times the Lambert shading."""
    from matplotlib import colormaps

    if values is not None:
        v = np.asarray(values, dtype=float)[F].mean(axis=1)
        span = np.ptp(v)
        t = (v - v.min()) / span if span > 1e-12 * max(np.abs(v).max(), 1e-300) else np.full_like(v, 0.5)
        base = colormaps[cmap](t)[:, :3]
    else:
        base = np.broadcast_to(np.asarray(color, dtype=float), (len(F), 3))
    return np.clip(base * face_shading(V, F)[:, None], 0, 1)


def draw_mesh(ax, mesh: Mesh, *, values: np.ndarray | None = None, cmap: str = "viridis",
              color=(0.75, 0.78, 0.85), elev: float = 20.0, azim: float = -60.0, alpha: float = 1.0,
              max_faces: int | None = None) -> None:
    """Draw ``mesh`` on a 3D axis, shaded; ``values`` (n,) colours it by a vertex function. ``max_faces``: a
    plain-coloured mesh with more faces is drawn decimated to about that many (a thumbnail: matplotlib keeps
    every face of every panel as a path, about 1 KB each, until the figure is closed)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    V, F = mesh.V, mesh.F
    if max_faces is not None and values is None and len(F) > max_faces:
        from topomatch.stages.mesh.decimate import simplify_to_target

        V, F, _ = simplify_to_target(V, F, max_faces)
    rgb = face_colors(V, F, values=values, cmap=cmap, color=color)
    poly = Poly3DCollection(V[F], facecolors=rgb, edgecolors="none", linewidths=0, alpha=alpha)
    ax.add_collection3d(poly)
    lo, hi = V.min(axis=0), V.max(axis=0)
    mid, half = (lo + hi) / 2, (hi - lo).max() / 2 or 1.0
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()
