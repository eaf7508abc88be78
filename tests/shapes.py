"""Small synthetic meshes with known answers, built in code (no files). Importable by tests as ``shapes``."""

from __future__ import annotations


import numpy as np

from topomatch.stages.mesh.mesh import Mesh


def octahedron() -> Mesh:
    """Regular octahedron with vertices at +-e_i: 6 vertices, 8 faces, 12 edges, outward normals."""
    V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
                  [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return Mesh(V, F, name="octahedron")


def icosphere(level: int = 1) -> Mesh:
    """Icosahedron subdivided ``level`` times (midpoints, igl.upsample), projected on the unit sphere."""
    import igl

    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    if level > 0:
        V, F = igl.upsample(V, F, number_of_subdivs=level)
    V = V / np.linalg.norm(V, axis=1, keepdims=True)
    return Mesh(V, F, name=f"icosphere{level}")


def unit_cube() -> Mesh:
    """The unit cube [0, 1]^3 as 12 outward-oriented triangles: area 6, 18 edges."""
    V = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return Mesh(V, F, name="cube")


def disjoint_union(*meshes: Mesh, offsets=None, name: str = "union") -> Mesh:
    """One mesh made of copies of ``meshes``, the i-th translated by ``offsets[i]`` (default 3 i e_x)."""
    Vs, Fs, n = [], [], 0
    for i, m in enumerate(meshes):
        off = np.array([3.0 * i, 0, 0]) if offsets is None else np.asarray(offsets[i], float)
        Vs.append(m.V + off)
        Fs.append(m.F + n)
        n += m.n_vertices
    return Mesh(np.vstack(Vs), np.vstack(Fs), name=name)


def soup(mesh: Mesh) -> Mesh:
    """Every face with its own three vertices (as STL stores it): 3 m vertices."""
    return Mesh(mesh.V[mesh.F].reshape(-1, 3), np.arange(3 * mesh.n_faces).reshape(-1, 3), name=mesh.name)


