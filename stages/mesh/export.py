"""Writing triangle meshes as text files other tools open: PLY (ASCII), OBJ and OFF.

Coordinates are written with 17 significant digits, so a written mesh reads back bit for bit.
"""

from __future__ import annotations

import numpy as np

#: The mesh file formats (the default, PLY, first).
MESH_FORMATS = ("ply", "obj", "off")


def mesh_text(V: np.ndarray, F: np.ndarray, fmt: str) -> str:
    """The mesh ``(V (n, 3), F (m, 3))`` as the text of a ``fmt`` file (one of :data:`MESH_FORMATS`)."""
    V = np.asarray(V, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(F, dtype=np.int64).reshape(-1, 3)
    verts = [f"{x:.17g} {y:.17g} {z:.17g}" for x, y, z in V]
    if fmt == "ply":
        lines = ["ply", "format ascii 1.0", f"element vertex {len(V)}", "property double x", "property double y",
                 "property double z", f"element face {len(F)}", "property list uchar int vertex_indices",
                 "end_header", *verts, *(f"3 {a} {b} {c}" for a, b, c in F)]
    elif fmt == "obj":
        lines = [f"v {v}" for v in verts] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]
    elif fmt == "off":
        lines = ["OFF", f"{len(V)} {len(F)} 0", *verts, *(f"3 {a} {b} {c}" for a, b, c in F)]
    else:
        raise ValueError(f"mesh format must be one of {', '.join(MESH_FORMATS)}, got {fmt!r}")
    return "\n".join(lines) + "\n"
