"""Reading meshes: every format round-trips through a reference writer; every failure names the file."""

from __future__ import annotations

import gzip
import shutil

import numpy as np
import pytest

from topomatch.pipeline.errors import InputError
from topomatch.stages.mesh.io import LoadParams, load, read_mesh


def _gzip(path):
    gz = path.with_name(path.name + ".gz")
    with open(path, "rb") as src, gzip.open(gz, "wb") as dst:
        shutil.copyfileobj(src, dst)
    return gz


@pytest.mark.parametrize("suffix,binary", [(".off", False), (".obj", False), (".ply", True), (".ply", False)])
@pytest.mark.parametrize("gzipped", [False, True])
def test_igl_written_files_read_back(tmp_path, bundled_mesh, suffix, binary, gzipped):
    import igl

    ref = bundled_mesh("torus.off")
    path = tmp_path / f"torus{suffix}"
    encoding = igl.FileEncoding.Binary if binary else igl.FileEncoding.Ascii
    igl.write_triangle_mesh(str(path), ref.V, ref.F, encoding)
    if gzipped:
        path = _gzip(path)
    mesh, reader = read_mesh(path)
    # libigl's ASCII PLY writer prints 6 significant digits; OFF/OBJ and binary PLY keep the values.
    rtol = 1e-5 if (suffix == ".ply" and not binary) else 1e-12
    np.testing.assert_allclose(mesh.V, ref.V, rtol=rtol, atol=1e-12)
    np.testing.assert_array_equal(mesh.F, ref.F)
    assert mesh.name == "torus"
    assert mesh.V.dtype == np.float64 and mesh.F.dtype == np.int64
    assert mesh.V.flags.c_contiguous and mesh.F.flags.c_contiguous


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("gzipped", [False, True])
def test_stl_reads_back_the_same_triangles(tmp_path, shapes, binary, gzipped):
    """STL stores each triangle with its own corners, so compare corner positions V[F]."""
    import igl

    ref = shapes.octahedron()
    path = tmp_path / "octa.stl"
    encoding = igl.FileEncoding.Binary if binary else igl.FileEncoding.Ascii
    igl.write_triangle_mesh(str(path), ref.V, ref.F, encoding)
    if gzipped:
        path = _gzip(path)
    mesh, _ = read_mesh(path)
    assert mesh.n_faces == ref.n_faces
    np.testing.assert_allclose(mesh.V[mesh.F], ref.V[ref.F], atol=1e-7)


@pytest.mark.parametrize("ascii", [True, False])
def test_open3d_written_ply_reads_back(tmp_path, bundled_mesh, ascii):
    import open3d as o3d

    from topomatch.stages.adapters.open3d_adapter import to_open3d

    ref = bundled_mesh("eight_genus2.off")
    path = tmp_path / "eight.ply"
    assert o3d.io.write_triangle_mesh(str(path), to_open3d(ref), write_ascii=ascii)
    mesh, _ = read_mesh(path)
    np.testing.assert_allclose(mesh.V, ref.V, atol=1e-6 * np.abs(ref.V).max())
    np.testing.assert_array_equal(mesh.F, ref.F)


@pytest.mark.parametrize("coordinate, count, index", [("float", "uchar", "int"), ("double", "uchar", "int"),
                                                       ("float32", "uint8", "uint32"), ("float", "ushort", "int"),
                                                       ("double", "int", "int")])
def test_big_endian_binary_ply_reads_as_the_mesh_it_holds(tmp_path, bundled_mesh, coordinate, count, index):
    # MeshLab misreads these (double coordinates as 1e306, a ushort list count as a truncated file); written here
    # by hand from the PLY specification, with a per-vertex property besides x, y, z
    ref = bundled_mesh("eight_genus2.off")
    types = {"float": ">f4", "float32": ">f4", "double": ">f8", "uchar": ">u1", "uint8": ">u1", "ushort": ">u2",
             "int": ">i4", "uint32": ">u4"}
    faces = list(ref.F)
    head = (f"ply\nformat binary_big_endian 1.0\nelement vertex {ref.n_vertices}\n"
            + "".join(f"property {coordinate} {a}\n" for a in ("x", "y", "z", "nx"))
            + f"element face {len(faces)}\nproperty list {count} {index} vertex_indices\nend_header\n")
    vertices = np.hstack([ref.V, np.zeros((ref.n_vertices, 1))]).astype(types[coordinate]).tobytes()
    body = b"".join(np.array([len(f)], types[count]).tobytes() + np.asarray(f).astype(types[index]).tobytes()
                    for f in faces)
    path = tmp_path / "eight.ply"
    path.write_bytes(head.encode() + vertices + body)
    mesh, used = read_mesh(path)
    assert used == "plyfile"
    np.testing.assert_allclose(mesh.V, ref.V, rtol=1e-6 if coordinate != "double" else 0)
    np.testing.assert_array_equal(mesh.F, ref.F)


def test_a_damaged_big_endian_ply_is_an_input_error(tmp_path, bundled_mesh):
    ref = bundled_mesh("eight_genus2.off")
    head = (f"ply\nformat binary_big_endian 1.0\nelement vertex {ref.n_vertices}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {ref.n_faces}\nproperty list uchar int vertex_indices\nend_header\n")
    body = ref.V.astype(">f4").tobytes() + b"".join(b"\x03" + f.astype(">i4").tobytes() for f in ref.F)
    rng = np.random.default_rng(1)
    for k in range(20):  # byte flips in the face lists: an error naming the file, never a crash or a traceback
        data = bytearray(body)
        at = len(ref.V) * 12 + int(rng.integers(0, ref.n_faces)) * 13
        data[at] = int(rng.integers(4, 255))  # a list count that is not 3: the rest of the faces shift
        path = tmp_path / f"bad{k}.ply"
        path.write_bytes(head.encode() + bytes(data))
        with pytest.raises(InputError, match=f"bad{k}\\.ply"):
            read_mesh(path)


def test_bundled_obj_gz_reads(bundled_mesh):
    mesh = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    assert mesh.name == "odedstein_spot_low_resolution"
    assert mesh.n_faces > 1000 and mesh.F.max() < mesh.n_vertices


def test_load_stage_result(tmp_path, shapes):
    import igl

    ref = shapes.octahedron()
    path = tmp_path / "octa.off"
    igl.write_triangle_mesh(str(path), ref.V, ref.F)
    result = load(str(path), params=LoadParams())
    assert result.summary() == {"vertices": 6, "faces": 8, "reader": "igl", "polygons_triangulated": 0}
    np.testing.assert_array_equal(result.mesh.F, ref.F)


def _expect_input_error(path, *fragments):
    with pytest.raises(InputError) as info:
        read_mesh(path)
    message = str(info.value)
    assert path.name in message
    for fragment in fragments:
        assert fragment in message
    return message


def test_missing_file(tmp_path):
    _expect_input_error(tmp_path / "nothere.off", "not found")


def test_empty_file(tmp_path):
    path = tmp_path / "empty.off"
    path.write_bytes(b"")
    _expect_input_error(path, "empty")


def test_empty_gz_file(tmp_path):
    path = tmp_path / "empty.off.gz"
    with gzip.open(path, "wb"):
        pass
    _expect_input_error(path, "empty")


def test_malformed_off(tmp_path):
    path = tmp_path / "broken.off"
    path.write_text("OFF\n3 1 0\n0 0 0\n1 0 zero\n")
    _expect_input_error(path)


def test_out_of_range_index(tmp_path):
    path = tmp_path / "badindex.off"
    path.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    _expect_input_error(path)


def test_unsupported_suffix(tmp_path):
    path = tmp_path / "mesh.xyz"
    path.write_text("0 0 0\n")
    _expect_input_error(path, "unsupported")


# --------------------------------------------------------------------------- structure checks: nothing silently wrong


def _write(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


QUAD = "OFF\n5 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n4 0 1 2 3\n3 0 1 4\n"


@pytest.mark.parametrize("name,text,message", [
    ("truncated.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n", "truncated, the header declares 4 vertices and 2"),
    ("undercounted.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n", "1 more lines follow"),
    ("huge_header.off", "OFF\n50000000 1 0\n0 0 0\n", "declares 50000000 vertices"),
    ("two.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 1\n3 0 1 2\n", "face 0 .* has 2 vertices"),
    ("two.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nf 1 2\n", "face 2 .* has 2 vertices"),
    ("nofaces.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\n", "no faces"),
    ("negative.off", "OFF\n-3 1 0\n", "negative"),
    ("short.stl", b"\0" * 80 + (1000).to_bytes(4, "little") + b"\0" * 60, "truncated binary STL"),
    ("short.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n",
     "truncated, the header declares 4 element lines but only 2"),
])
def test_malformed_structure_is_an_error_not_a_partial_mesh(tmp_path, name, text, message):
    with pytest.raises(InputError, match=f"{name}: .*{message}"):
        read_mesh(_write(tmp_path, name, text))


def test_truncated_file_is_not_rescued_by_open3d(tmp_path, bundled_mesh):
    """libigl rejects a truncated OFF; open3d would read part of it: the load fails instead."""
    import igl

    torus = bundled_mesh("torus.off")
    path = tmp_path / "torus.off"
    igl.write_triangle_mesh(str(path), torus.V, torus.F)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[: 2 + torus.n_vertices + 300]) + "\n")
    with pytest.raises(InputError, match="truncated"):
        read_mesh(path)


def test_polygons_are_triangulated_and_counted(tmp_path):
    result = load(str(_write(tmp_path, "quad.off", QUAD)), params=LoadParams())
    assert result.mesh.n_faces == 3 and result.polygons == 1
    assert result.summary()["polygons_triangulated"] == 1


def test_decompressed_size_is_capped(tmp_path, monkeypatch):
    path = tmp_path / "bomb.off.gz"
    with gzip.open(path, "wb") as fh:
        fh.write(b"OFF\n" + b" " * 3_000_000)
    monkeypatch.setenv("TOPOMATCH_MAX_MESH_BYTES", "1000000")
    with pytest.raises(InputError, match="bomb.off.gz: decompresses to more than 1 MiB"):
        read_mesh(path)


OCTA = ("OFF\n6 8 0\n1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n"
        "3 0 2 4\n3 2 1 4\n3 1 3 4\n3 3 0 4\n3 2 0 5\n3 1 2 5\n3 3 1 5\n3 0 3 5\n")


def _octa_stl(name: str) -> str:
    V = [[float(x) for x in line.split()] for line in OCTA.splitlines()[2:8]]
    F = [[int(x) for x in line.split()[1:]] for line in OCTA.splitlines()[8:]]
    body = "".join(" facet normal 0 0 0\n  outer loop\n" + "".join("   vertex %g %g %g\n" % tuple(V[i]) for i in f)
                   + "  endloop\n endfacet\n" for f in F)
    return f"solid {name}\n{body}endsolid {name}\n"


@pytest.mark.parametrize("name,content", [
    ("comment-before-header.off", "# written by hand\n\n# second comment\n" + OCTA),
    ("byte-order-mark.off", "\ufeff" + OCTA),
    ("byte-order-mark.obj", "\ufeff" + "".join(f"v {l}\n" for l in OCTA.splitlines()[2:8])
     + "".join("f " + " ".join(str(int(i) + 1) for i in l.split()[1:]) + "\n" for l in OCTA.splitlines()[8:])),
    ("keyword-in-name.stl", _octa_stl("vertex_model")),
    ("upper-case.stl", _octa_stl("x").upper()),
])
def test_format_variants_the_readers_refuse_are_read(tmp_path, name, content):
    """Variants the formats allow but libigl refuses read as the same octahedron: 6 vertices, 8 faces,
    a closed surface (Euler characteristic 2)."""
    path = tmp_path / name
    path.write_text(content, encoding="utf-8")
    mesh = read_mesh(path)[0]
    V = np.unique(np.round(mesh.V, 9), axis=0)
    assert len(V) == 6 and mesh.n_faces == 8
    assert np.allclose(np.sort(np.abs(V).sum(axis=1)), 1.0)


def test_polygon_ply_is_read_not_aborted(tmp_path):
    """A PLY with a quad: libigl's reader aborts the process on it; the quad is split in two."""
    text = ("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
            "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
    path = tmp_path / "quad.ply"
    path.write_text(text)
    mesh = read_mesh(path)[0]
    import igl

    assert mesh.n_faces == 2 and np.isclose(igl.doublearea(mesh.V, mesh.F).sum() / 2, 1.0)


def test_ascii_line_scan_agrees_with_python_split():
    """The vectorised scan of ASCII PLY bodies sees the lines ``bytes.splitlines`` sees, the tokens ``bytes.split``
    sees, and a leading b"3" exactly where Python's first token is b"3" (fuzzed bytes, every whitespace kind)."""
    from topomatch.stages.mesh.file_checks import _ascii_lines

    rng = np.random.default_rng(0)
    alphabet = [b" ", b"\t", b"\n", b"\r", b"\x0b", b"\x0c", b"3", b"4", b"1", b"-", b"33", b"3.5"]
    for _ in range(2000):
        data = b"".join(rng.choice(alphabet, size=int(rng.integers(0, 40))).tolist())
        first, end, tokens, triangle = _ascii_lines(data)
        lines = [line for line in data.splitlines() if line.strip()]
        assert [data[a:b].strip() for a, b in zip(first, end)] == [line.strip() for line in lines]
        assert tokens.tolist() == [len(line.split()) for line in lines]
        assert triangle.tolist() == [line.split()[0] == b"3" for line in lines]
