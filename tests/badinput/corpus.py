"""The bad-input corpus: every way a hostile or careless user can feed ``topomatch`` bad input.

Each :class:`Case` writes its own small files into a fresh folder, names one command line and
what the command must answer: its exit status and a pattern its error output must contain.
``tests/badinput/test_corpus.py`` runs every case as a user would (a subprocess of the installed
command) and also checks that no traceback is printed; ``benchmarks/bad_inputs.py`` runs the same
cases and measures the time and peak memory of each.

Placeholders in ``argv``: ``{d}`` the case's folder, ``{meshes}`` the bundled meshes, ``{itk}``
the bundled ITK slices, ``{db}`` a copy of a small valid index, ``{run}`` a copy of a finished
run's output folder (the config is ``{d}/ok.yaml``).
"""

from __future__ import annotations

import gzip
import json
import os
import sqlite3
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

REPO = Path(__file__).resolve().parents[2]
MESHES = REPO / "data" / "meshes"
ITK = REPO / "data" / "images" / "itk"

OCTAHEDRON = ("OFF\n6 8 0\n1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n"
              "3 0 2 4\n3 2 1 4\n3 1 3 4\n3 3 0 4\n3 2 0 5\n3 1 2 5\n3 3 1 5\n3 0 3 5\n")
OCTA_V = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
OCTA_F = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]


@dataclass(frozen=True)
class Case:
    """One bad input: files to write, the command, the expected exit status and message."""

    id: str
    kind: str  # mesh | config | image | cli | database | cache
    argv: list[str]
    code: int
    message: str  # a regular expression searched in stderr + stdout
    files: dict[str, bytes | str | Callable[[Path], None]] = field(default_factory=dict)
    needs: tuple[str, ...] = ()  # shared assets: "db", "run"


def _off(V, F, header: str | None = None) -> str:
    head = header if header is not None else f"{len(V)} {len(F)} 0"
    lines = ["OFF", head] + [" ".join(repr(float(x)) for x in v) for v in V]
    lines += [f"{len(f)} " + " ".join(str(i) for i in f) for f in F]
    return "\n".join(lines) + "\n"


def _obj(V, F) -> str:
    return "".join(f"v {x} {y} {z}\n" for x, y, z in V) + "".join("f " + " ".join(map(str, f)) + "\n" for f in F)


def _ply_ascii(V, F, n_v=None, n_f=None) -> str:
    head = (f"ply\nformat ascii 1.0\nelement vertex {n_v if n_v is not None else len(V)}\nproperty float x\n"
            f"property float y\nproperty float z\nelement face {n_f if n_f is not None else len(F)}\n"
            "property list uchar int vertex_indices\nend_header\n")
    return head + "".join(f"{x} {y} {z}\n" for x, y, z in V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in F)


def _ply_binary(n_v: int, n_f: int, payload: bytes) -> bytes:
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {n_v}\nproperty float x\nproperty float y\n"
            f"property float z\nelement face {n_f}\nproperty list uchar int vertex_indices\nend_header\n")
    return head.encode() + payload


def _stl_binary(n_triangles: int, stored: int) -> bytes:
    tri = struct.pack("<12fH", *([0.0] * 3 + [0, 0, 0, 1, 0, 0, 0, 1, 0]), 0)
    return b"\0" * 80 + struct.pack("<I", n_triangles) + tri * stored


def _png(width: int, height: int, pixels: bytes | None = None, *, declared: tuple[int, int] | None = None) -> bytes:
    """A grey 8-bit PNG; ``declared`` overrides the header's size (a lie about the pixels)."""
    w, h = declared or (width, height)
    raw = pixels if pixels is not None else b"".join(b"\0" + bytes((x * 7 + y * 3) % 256 for x in range(width))
                                                      for y in range(height))

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def _png_1bit(width: int, height: int) -> bytes:
    """A 1-bit PNG of ``width`` x ``height`` zero pixels: a few kilobytes that decode to a huge array."""
    row = b"\0" + b"\0" * ((width + 7) // 8)

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(row * height, 9)) + chunk(b"IEND", b""))


def _nifti(data: np.ndarray) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        import nibabel as nib

        nib.save(nib.Nifti1Image(np.asarray(data), np.eye(4)), str(path))
    return write


def _gzip_bomb(path: Path) -> None:
    """A .off.gz that inflates to 600 MiB (over the 512 MiB cap) from ~600 KB."""
    with gzip.open(path, "wb", compresslevel=9) as fh:
        fh.write(b"OFF\n6 8 0\n")
        block = b" " * (1 << 20)
        for _ in range(600):
            fh.write(block)


def _sqlite(path: Path, statements: list[str]) -> None:
    con = sqlite3.connect(path)
    for s in statements:
        con.execute(s)
    con.commit()
    con.close()


def _corrupt_pages(path: Path) -> None:
    data = bytearray(path.read_bytes())
    for offset in range(4096, len(data), 4096):  # every page after the first: its header and cells
        data[offset:offset + 64] = b"\xff" * 64
    path.write_bytes(bytes(data))


def _truncate_half(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _pickle_blob(path: Path) -> None:
    import pickle

    con = sqlite3.connect(path)
    table = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")]
    for name in table:
        cols = [r[1] for r in con.execute(f"PRAGMA table_info({name})")]
        for col in cols:
            kinds = {r[0] for r in con.execute(f"SELECT typeof({col}) FROM {name}")}
            if "blob" in kinds:
                con.execute(f"UPDATE {name} SET {col} = ?", (pickle.dumps({"evil": object.__name__}),))
    con.commit()
    con.close()


def _descriptor(change: Callable[[np.ndarray], object]) -> Callable[[Path], None]:
    """Replace the stored descriptor of the index's first ok row by ``change(descriptor)``: an array (saved as
    topomatch saves one), raw bytes, or None (NULL)."""
    import io as _io

    def damage(path: Path) -> None:
        con = sqlite3.connect(path)
        row_id, blob = con.execute("SELECT id, descriptor FROM shapes WHERE status = 'ok' ORDER BY id").fetchone()
        new = change(np.load(_io.BytesIO(blob), allow_pickle=False))
        if isinstance(new, np.ndarray):
            buf = _io.BytesIO()
            np.save(buf, new, allow_pickle=False)
            new = buf.getvalue()
        con.execute("UPDATE shapes SET descriptor = ? WHERE id = ?", (new, row_id))
        con.commit()
        con.close()
    return damage


def _nan_first(d: np.ndarray) -> np.ndarray:
    d = d.astype(np.float64)
    d.flat[0] = np.nan
    return d


def _damage_cache(how: str) -> Callable[[Path], None]:
    """Damage every entry of the run's cache (``{d}/out/.cache``)."""
    def damage(d: Path) -> None:
        for entry in (d / "out" / ".cache").rglob("*"):
            if not entry.is_file():
                continue
            if how == "truncate":
                _truncate_half(entry)
            elif how == "garbage":
                entry.write_bytes(b"not a cache entry")
            elif how == "empty":
                entry.write_bytes(b"")
            elif how == "json" and entry.suffix == ".json":
                entry.write_text("{not json")
            elif how == "pickle" and entry.suffix == ".npz":
                np.savez(entry, evil=np.array([object()], dtype=object))
    return damage


def mesh_cases() -> list[Case]:
    V, F = OCTA_V, OCTA_F
    sk = ["skeleton", "{d}/m"]
    cases: list[tuple[str, str, bytes | str | Callable[[Path], None], str]] = [
        ("empty-off", "m.off", "", r"m\.off: .*(empty|no |header)"),
        ("empty-obj", "m.obj", "", r"m\.obj: .*(empty|no vertices|no faces)"),
        ("empty-ply", "m.ply", "", r"m\.ply: "),
        ("empty-stl", "m.stl", "", r"m\.stl: "),
        ("off-bad-magic", "m.off", OCTAHEDRON.replace("OFF", "OFX", 1), r"m\.off: "),
        ("off-negative-counts", "m.off", _off(V, F, "-6 8 0"), r"m\.off: "),
        ("off-huge-header", "m.off", "OFF\n50000000 1 0\n0 0 0\n3 0 0 0\n", r"m\.off: .*(50000000|claims|vertices)"),
        ("off-huge-faces", "m.off", "OFF\n3 90000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", r"m\.off: .*(90000000|faces)"),
        ("off-truncated-vertices", "m.off", _off(V, F)[:40], r"m\.off: "),
        ("off-truncated-faces", "m.off", "\n".join(_off(V, F).splitlines()[:10]) + "\n", r"m\.off: .*face"),
        ("off-undercounted-faces", "m.off", _off(V, F, "6 4 0"), r"m\.off: .*(face|lines)"),
        ("off-overcounted-vertices", "m.off", _off(V, F, "9 8 0"), r"m\.off: "),
        ("off-two-vertex-face", "m.off", _off(V, F[:-1] + [[0, 1]]), r"m\.off: .*(2 vertices|fewer than 3|at least 3)"),
        ("off-index-out-of-range", "m.off", _off(V, F[:-1] + [[0, 3, 99]]), r"m\.off: .*(99|index|range)"),
        ("off-negative-index", "m.off", _off(V, F[:-1] + [[0, 3, -2]]), r"m\.off: .*(-2|index|negative|range)"),
        ("off-nan-coordinate", "m.off", _off([[float("nan"), 0, 0]] + V[1:], F), r"m\.off: .*(NaN|nan|finite)"),
        ("off-inf-coordinate", "m.off", _off([[float("inf"), 0, 0]] + V[1:], F), r"m\.off: .*(inf|finite)"),
        ("off-text-coordinate", "m.off", _off(V, F).replace("-1.0 0.0 0.0", "minus one 0 0"), r"m\.off: "),
        ("off-one-point", "m.off", _off([[0, 0, 0]] * 6, F), r"m\.off: .*(one point|degenerate|no faces)"),
        ("off-line", "m.off", _off([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]]), r"m\.off: .*(no faces left|degenerate)"),
        ("off-single-triangle", "m.off", _off([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]), r"m\.off: .*too few"),
        ("off-huge-scale", "m.off", _off(np.array(V) * 1e300, F), r"m\.off: .*units across.*overflow"),
        ("off-tiny-scale", "m.off", _off(np.array(V) * 1e-300, F), r"m\.off: .*units across.*underflow"),
        ("off-no-faces", "m.off", _off(V, []), r"m\.off: .*(no faces|faces)"),
        ("off-binary-garbage", "m.off", bytes(range(256)) * 4, r"m\.off: "),
        ("off-gz-truncated", "m.off.gz", gzip.compress(OCTAHEDRON.encode())[:30], r"m\.off\.gz: "),
        ("off-gz-not-gzip", "m.off.gz", OCTAHEDRON, r"m\.off\.gz: "),
        ("off-gz-bomb", "m.off.gz", _gzip_bomb, r"m\.off\.gz: .*(MiB|TOPOMATCH_MAX_MESH_BYTES|cap|larger)"),
        ("unsupported-extension", "m.xyz", "0 0 0\n", r"m\.xyz: .*(format|extension|unsupported)"),
        ("obj-missing-vertex", "m.obj", _obj(V, [[1, 3, 5], [1, 2, 40]]), r"m\.obj: "),
        ("obj-no-faces", "m.obj", _obj(V, []), r"m\.obj: .*(no faces|faces)"),
        ("obj-two-vertex-face", "m.obj", _obj(V, [[1, 3, 5], [1, 2]]), r"m\.obj: "),
        ("obj-nan", "m.obj", _obj([["nan", 0, 0]] + V[1:], [[1, 3, 5], [2, 3, 5]]), r"m\.obj: .*(NaN|nan|finite|line 1)"),
        ("obj-garbage", "m.obj", "this is not a mesh\n" * 20, r"m\.obj: "),
        ("ply-huge-count", "m.ply", _ply_binary(1_000_000_000, 1, b"\0" * 64), r"m\.ply: "),
        ("ply-truncated-binary", "m.ply", _ply_binary(6, 8, b"\0" * 30), r"m\.ply: "),
        ("ply-ascii-wrong-counts", "m.ply", _ply_ascii(V, F, n_v=60, n_f=80), r"m\.ply: "),
        ("stl-huge-count", "m.stl", _stl_binary(1_000_000_000, 2), r"m\.stl: "),
        ("stl-truncated", "m.stl", _stl_binary(10, 3), r"m\.stl: "),
        ("stl-ascii-garbage", "m.stl", "solid x\n  facet banana\nendsolid\n", r"m\.stl: "),
        ("stl-trailing-bytes", "m.stl", _stl_binary(1, 1) + b"\0" * 7, r"m\.stl: .*7 bytes of trailing data"),
        ("ply-format-blank", "m.ply", _ply_ascii(V, F).replace("format ascii 1.0", "format "),
         r"m\.ply: .*'format ascii 1\.0'"),
        ("ply-no-format", "m.ply", _ply_ascii(V, F).replace("format ascii 1.0\n", ""), r"m\.ply: .*no 'format' line"),
        ("ply-uchar-index-overflow", "m.ply", _ply_ascii(V, [[259, 2, 4]] + F[1:]).replace(
            "list uchar int", "list uchar uchar"), r"m\.ply: .*(index|259)"),
        ("ply-polygon-list-mismatch", "m.ply", _ply_ascii(V, F).replace("3 0 2 4\n", "5 0 2 4\n"), r"m\.ply: "),
        ("off-index-wraps-32-bit", "m.off", _off(V, [[2**32, 2, 4]] + F[1:]), r"m\.off: .*4294967296.*32-bit"),
        ("obj-index-wraps-32-bit", "m.obj", _obj(V, F[1:] + [[2**32 + 1, 3, 5]]), r"m\.obj: .*4294967297.*32-bit"),
        ("off-many-bad-lines", "m.off", "OFF\n1200 1 0\n" + "a b c\n" * 1200 + "3 0 1 2\n",
         r"m\.off: .*bad line.*\(x1200\)"),
        ("off-gz-ratio-bomb", "m.off.gz", gzip.compress(b"OFF\n6 8 0\n" + b"\0" * (40 << 20), 9),
         r"m\.off\.gz: .*decompression bomb"),
    ]
    out = []
    for cid, name, content, message in cases:
        argv = ["skeleton", "{d}/" + name]
        out.append(Case(f"mesh-{cid}", "mesh", argv, 1, message, {name: content}))
    del sk
    out += [
        Case("mesh-missing", "mesh", ["skeleton", "{d}/none.off"], 1, r"none\.off: file not found"),
        Case("mesh-directory", "mesh", ["skeleton", "{d}"], 1, r"not a regular file"),
        Case("mesh-match-one-bad", "mesh", ["match", "{meshes}/torus.off", "{d}/m.off"], 1, r"m\.off: ",
             {"m.off": "OFF\n3 1 0\n0 0 0\n"}),
        Case("mesh-query-bad", "mesh", ["query", "{d}/m.off", "--db", "{db}", "--method", "d2"], 1, r"m\.off: ",
             {"m.off": "OFF\n3 1 0\n0 0 0\n"}, needs=("db",)),
        Case("mesh-index-some-bad", "mesh", ["index", "{d}/in", "--db", "{d}/x.db", "--method", "d2"], 1,
             r"(1 failed|failed).*", {"in/bad.off": "OFF\n3 1 0\n0 0 0\n", "in/good.off": OCTAHEDRON}),
        Case("mesh-non-manifold-warns", "mesh", ["skeleton", "{d}/m.off"], 0, r"warning: .*non-manifold",
             {"m.off": _off(np.vstack([OCTA_V, np.array(OCTA_V) + [2, 0, 0]]),
                            OCTA_F + [[0 if i == 1 else i + 6 for i in f] for f in OCTA_F])}),
    ]
    return out


BASE_CONFIG = {
    "name": "bad",
    "inputs": {"meshes": ["{d}/ok.off"]},
    "stages": ["load", "clean", "measures"],
}


def _yaml(obj) -> str:
    import yaml

    return yaml.safe_dump(obj, sort_keys=False)


def _with(**changes) -> str:
    cfg = json.loads(json.dumps(BASE_CONFIG))
    cfg.update(changes)
    return _yaml(cfg)


_PAIRS_CONFIG = _yaml({"name": "pairs", "inputs": {"pairs_csv": {"path": "{d}/p.csv", "truth_columns": {"tx": "tx"},
                                                                  "skip_missing_truth": False}},
                        "stages": ["load_pair"]})


def _pairs_tables() -> list[tuple[str, str | bytes, str]]:
    """Damaged pair tables: (case id, content, expected message)."""
    png = str(ITK / "BrainProtonDensitySlice.png")
    row = f"{png},{png},1.5\n"
    return [
        ("empty", "fixed,moving,tx\n", "the pairs table has no rows"),
        ("short-row", "fixed,moving,tx\n" + row + f"{png}\n", "row 3: too few cells"),
        ("long-row", "fixed,moving,tx\n" + f"{png},{png},1,2\n", "row 2: too many cells"),
        ("unclosed-quote", "fixed,moving,tx\n" + f'"{png},{png},1\n', "(malformed CSV|too few cells)"),
        ("latin1", ("fixed,moving,tx\n" + row).encode() + "caf\xe9\n".encode("latin-1"), "not a UTF-8 text file"),
        ("nan-truth", "fixed,moving,tx\n" + f"{png},{png},nan\n", "row 2: truth is not a finite number"),
        ("text-truth", "fixed,moving,tx\n" + f"{png},{png},ten\n", "row 2: truth is not a number"),
        ("missing-column", "fixed,moving\n" + f"{png},{png}\n", "row 2: no column 'tx'"),
    ]


def config_cases() -> list[Case]:
    laughs = "a: &a [x,x,x,x,x,x,x,x,x,x]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [{','.join(['*' + chr(97 + i)] * 10)}]\n" for i in range(8))
    deep = "a: " + "[" * 5000 + "]" * 5000 + "\n"
    base = _with()
    cases = [
        ("empty", "", 2, r"c\.yaml: .*(empty|mapping)"),
        ("list", "- a\n- b\n", 2, r"c\.yaml: .*mapping"),
        ("scalar", "just a string\n", 2, r"c\.yaml: .*mapping"),
        ("syntax", "name: [unclosed\n", 2, r"c\.yaml: .*(line|YAML|parse)"),
        ("tabs", "name: x\n\tstages: []\n", 2, r"c\.yaml: "),
        ("duplicate-key", base + "stages: [load]\n", 2, r"duplicate key 'stages'"),
        ("billion-laughs", laughs, 2, r"c\.yaml: .*(alias|expan|large)"),
        ("deep-nesting", deep, 2, r"c\.yaml: .*(deep|nest)"),
        ("python-tag", "name: !!python/object/apply:os.system ['echo pwned']\n", 2, r"c\.yaml: "),
        ("binary", bytes(range(256)) * 10, 2, r"c\.yaml: "),
        ("latin1", "name: caf\xe9\n".encode("latin-1"), 2, r"c\.yaml: .*(UTF-8|utf-8|decode|encoding)"),
        ("unknown-top-key", _with(stagez=["load"]), 2, r"stagez"),
        ("missing-stages", _yaml({"name": "x", "inputs": {"meshes": ["{d}/ok.off"]}}), 2, r"stages"),
        ("missing-inputs", _yaml({"name": "x", "stages": ["load"]}), 2, r"inputs"),
        ("unknown-stage", _with(stages=["load", "teleport"]), 2, r"teleport"),
        ("stage-param-type", _with(stages=["load", {"noise": {"sigma": "a lot"}}]), 2, r"noise.*sigma"),
        ("stage-param-negative", _with(stages=["load", {"noise": {"sigma": -1}}]), 2, r"sigma"),
        ("stage-param-nan", _with(stages=["load", {"noise": {"sigma": float("nan")}}]), 2, r"sigma"),
        ("stage-unknown-param", _with(stages=["load", {"clean": {"colour": "red"}}]), 2, r"colour"),
        ("stage-not-mapping", _with(stages=["load", {"clean": [1, 2]}]), 2, r"clean"),
        ("stage-two-keys", _with(stages=["load", {"clean": {}, "measures": {}}]), 2, r"(one stage|clean|measures)"),
        ("stage-input-missing", _with(stages=["load", "level_sets"]), 2, r"(level_sets|function|produce)"),
        ("sweep-not-list", _with(sweep={"noise.sigma": 0.1}, stages=["load", "noise"]), 2, r"sweep"),
        ("sweep-unknown-key", _with(sweep={"noise.sigmaa": [0.1]}, stages=["load", "noise"]), 2, r"sigmaa"),
        ("sweep-bad-value", _with(sweep={"noise.sigma": ["big"]}, stages=["load", "noise"]), 2, r"sigma"),
        ("sweep-stage-absent", _with(sweep={"decimate.ratio": [0.5]}), 2, r"decimate"),
        ("report-unknown", _with(reports=["pie_chart"]), 2, r"pie_chart"),
        ("report-bad-params", _with(reports=[{"table": {"name": 3, "columns": "x"}}]), 2, r"table"),
        ("inputs-missing-file", _with(inputs={"meshes": ["{d}/none.off"]}), 1, r"none\.off"),
        ("inputs-glob-nothing", _with(inputs={"meshes": ["{d}/*.nothing"]}), 1, r"no file matches this pattern"),
        ("inputs-wrong-type", _with(inputs={"meshes": 42}), 2, r"meshes"),
        ("name-not-string", _with(name=["a"]), 2, r"name"),
        ("executor-unknown", _with(executor={"kind": "quantum"}), 2, r"quantum"),
        ("executor-address-local", _with(executor={"kind": "local", "address": "tcp://127.0.0.1:8786"}), 2,
         r"c\.yaml: executor\.address \(--address\) applies only to the dask executor, and the executor is local"),
        ("executor-workers-with-address", _with(executor={"kind": "dask", "address": "tcp://127.0.0.1:8786", "workers": 2}),
         2, r"executor\.workers \(2, --workers\) does not apply with the dask scheduler at tcp://127\.0\.0\.1:8786"),
        ("data-root-unset", _with(inputs={"meshes": ["{data_root}/x.off"]}), 2, r"data.root|TOPOMATCH_DATA_ROOT"),
        ("sweep-too-large", _with(sweep={"noise.sigma": list(range(30)), "noise.seed": list(range(30)),
                                         "clean.merge_tolerance": [0.0] * 30}, stages=["load", "clean", "noise"]),
         2, r"the sweep has 27,000 points"),
    ]
    out = []
    for cid, text, code, message in cases:
        files = {"c.yaml": text, "ok.off": OCTAHEDRON}
        command = "run" if code == 1 else "validate"
        argv = [command, "{d}/c.yaml"] + (["--out", "{d}/out", "--no-progress"] if command == "run" else [])
        out.append(Case(f"config-{cid}", "config", argv, code, message, files))
    ok = {"c.yaml": base, "ok.off": OCTAHEDRON}
    out += [
        Case("config-huge", "config", ["validate", "{d}/c.yaml"], 2, r"c\.yaml: .*(large|MiB|size)",
             {"c.yaml": "# " + "x" * (5 << 20) + "\n" + base, "ok.off": OCTAHEDRON}),
        Case("config-missing", "config", ["run", "{d}/none.yaml"], 1, r"none\.yaml: config file not found"),
        Case("config-directory", "config", ["run", "{d}"], 1, r"(directory|not a file|folder)"),
        Case("config-set-malformed", "config", ["run", "{d}/c.yaml", "--set", "novalue"], 2, r"KEY=VALUE|novalue", ok),
        Case("config-set-unknown", "config", ["run", "{d}/c.yaml", "--set", "clean.colour=red"], 2, r"colour", ok),
        Case("config-set-bad-value", "config", ["run", "{d}/c.yaml", "--set", "clean.merge_tolerance=abc"], 2,
             r"merge_tolerance", ok),
        Case("config-set-absent-stage", "config", ["run", "{d}/c.yaml", "--set", "noise.sigma=0.1"], 2, r"noise", ok),
        Case("config-out-is-file", "config", ["run", "{d}/c.yaml", "--out", "{d}/ok.off", "--no-progress"], 1,
             r"ok\.off/.*a file is in the way", ok),
        Case("config-out-proc", "config", ["run", "{d}/c.yaml", "--out", "/proc/topomatch", "--no-progress"], 1,
             r"/proc/topomatch", ok),
        Case("config-cache-dev-null", "config", ["run", "{d}/c.yaml", "--out", "{d}/out", "--cache-dir",
                                                 "/dev/null/cache", "--no-progress"], 1, r"/dev/null.*a file is in the way", ok),
        Case("config-bad-mesh-item", "config", ["run", "{d}/c.yaml", "--out", "{d}/out", "--no-progress"], 1,
             r"1 of 2 items failed", {"c.yaml": _with(inputs={"meshes": ["{d}/ok.off", "{d}/bad.off"]}),
                                      "ok.off": OCTAHEDRON, "bad.off": "OFF\n3 1 0\n"}),
        Case("config-template-format-spec", "config", ["run", "{d}/c.yaml", "--out", "{d}/out", "--no-progress"], 2,
             r"unknown placeholder '\{bundled:>1000000000\}'",
             {"c.yaml": _with(inputs={"meshes": ["{bundled:>1000000000}/x.off"]})}),
        Case("config-dask-bad-address", "config", ["run", "{d}/c.yaml", "--out", "{d}/out", "--no-progress"], 2,
             r"executor\.address: cannot reach the dask scheduler .*unknown address scheme",
             {"c.yaml": _with(executor={"kind": "dask", "address": "zzz://bad address"}), "ok.off": OCTAHEDRON}),
        Case("config-set-on-malformed-sweep", "config", ["run", "{d}/c.yaml", "--set", "sweep.noise.sigma=[1]"], 2,
             r"'sweep' is a list, not a mapping", {"c.yaml": base + "sweep: [1, 2]\n"}),
        Case("config-set-on-malformed-stages", "config", ["run", "{d}/c.yaml", "--set", "noise.sigma=1"], 2,
             r"'stages' is a str, not a list", {"c.yaml": base.replace("stages:", "old_stages:") + "stages: load\n"}),
        *[Case(f"config-pairs-csv-{cid}", "config", ["run", "{d}/c.yaml", "--out", "{d}/out", "--no-progress"], 1,
               rf"p\.csv: {message}", {"c.yaml": _PAIRS_CONFIG, "p.csv": table})
          for cid, table, message in _pairs_tables()],
        Case("config-data-root-missing", "config", ["run", "{d}/c.yaml", "--data-root", "{d}/nowhere"], 1,
             r"nowhere", {"c.yaml": _with(inputs={"meshes": ["{data_root}/x.off"]}), "ok.off": OCTAHEDRON}),
    ]
    return out


def image_cases() -> list[Case]:
    fixed = "{itk}/BrainProtonDensitySlice.png"
    rng = np.random.default_rng(0)
    noise = _png(120, 140, b"".join(b"\0" + bytes(rng.integers(0, 256, 120, dtype=np.uint8)) for _ in range(140)))
    constant = _png(64, 64, b"".join(b"\0" + b"\x80" * 64 for _ in range(64)))
    nan_img = np.ones((40, 50), np.float32)
    nan_img[3, 4] = np.nan
    inf_img = np.ones((40, 50), np.float32) * np.arange(50)
    inf_img[5, 5] = np.inf
    cases = [
        ("missing", None, ["{d}/none.png"], r"none\.png: file not found"),
        ("empty", {"m.png": b""}, ["{d}/m.png"], r"m\.png: "),
        ("garbage-png", {"m.png": b"\x89PNG\r\n\x1a\nthis is not a png at all"}, ["{d}/m.png"], r"m\.png: "),
        ("text-as-png", {"m.png": "hello\n" * 100}, ["{d}/m.png"], r"m\.png: "),
        ("truncated-png", {"m.png": _png(100, 100)[:60]}, ["{d}/m.png"], r"m\.png: "),
        ("png-size-lie", {"m.png": _png(10, 10, declared=(60000, 60000))}, ["{d}/m.png"], r"m\.png: "),
        ("constant", {"m.png": constant}, ["{d}/m.png"], r"m\.png: .*constant"),
        ("tiny", {"m.png": _png(3, 3)}, ["{d}/m.png"], r"m\.png: .*(small|4)"),
        ("one-row", {"m.png": _png(50, 1)}, ["{d}/m.png"], r"m\.png: .*(small|4)"),
        ("nan-nifti", {"m.nii": _nifti(nan_img.T)}, ["{d}/m.nii"], r"m\.nii: .*(NaN|infinite)"),
        ("inf-nifti", {"m.nii": _nifti(inf_img.T)}, ["{d}/m.nii"], r"m\.nii: .*(NaN|infinite)"),
        ("volume-no-slice", {"m.nii": _nifti(rng.random((20, 30, 10)).astype(np.float32))}, ["{d}/m.nii"],
         r"m\.nii: .*(3D|slice)"),
        ("volume-slice-range", {"m.nii": _nifti(rng.random((20, 30, 10)).astype(np.float32))},
         ["{d}/m.nii", "--moving-slice", "10"], r"m\.nii: slice 10 is out of range"),
        ("4d", {"m.nii": _nifti(rng.random((10, 12, 5, 3)).astype(np.float32))}, ["{d}/m.nii", "--moving-slice", "1"],
         r"m\.nii: is a 4D image"),
        ("nii-truncated", {"m.nii": lambda p: (_nifti(rng.random((30, 30)).astype(np.float32))(p), _truncate_half(p))},
         ["{d}/m.nii"], r"m\.nii: "),
        ("nii-garbage", {"m.nii": b"\0" * 400}, ["{d}/m.nii"], r"m\.nii: "),
        ("unsupported", {"m.xyz": b"abc"}, ["{d}/m.xyz"], r"m\.xyz: "),
        ("directory", {"sub/x.txt": "x"}, ["{d}/sub"], r"sub: is a folder without a DICOM series"),
        ("png-1bit-bomb", {"m.png": _png_1bit(11000, 11000)}, ["{d}/m.png"],
         r"m\.png: the header declares 11000 x 11000 .*TOPOMATCH_MAX_IMAGE_PIXELS"),
        ("metaimage-dev-zero", {"m.mhd": "ObjectType = Image\nNDims = 2\nDimSize = 20000 20000\n"
                                         "ElementType = MET_UCHAR\nElementDataFile = /dev/zero\n"}, ["{d}/m.mhd"],
         r"m\.mhd: cannot read image \(its MetaImage header: its pixel data file /dev/zero .* not a regular file"),
        ("noise-flagged", {"m.png": noise}, ["{d}/m.png"], r"registration flagged"),
        ("shifted-out-of-view", {"m.png": _shifted_pd(150, 45)}, ["{d}/m.png"], r"registration flagged: .*content"),
    ]
    out = []
    for cid, files, moving, message in cases:
        out.append(Case(f"image-{cid}", "image", ["register", fixed, *moving], 1, message, files or {}))
    out += [
        Case("image-fixed-slice-on-2d", "image", ["register", fixed, fixed, "--fixed-slice", "2"], 1,
             r"is a 2D image .*applies only to a 3D volume"),
        Case("image-out-is-file", "image", ["register", fixed, fixed, "--out", "{d}/f.txt"], 1,
             r"f\.txt: .*(file is in the way|Not a directory|exists)", {"f.txt": "x"}),
        Case("image-dims-differ", "image", ["register", fixed, "{d}/m.nii", "--moving-slice", "-1"], 1, r"(3D|2D|slice)",
             {"m.nii": _nifti(rng.random((20, 30, 10, 2)).astype(np.float32))}),
    ]
    return out


def _shifted_pd(dx: int, dy: int) -> Callable[[Path], None]:
    def write(path: Path) -> None:
        from PIL import Image as PILImage

        pd = np.asarray(PILImage.open(ITK / "BrainProtonDensitySlice.png"))
        out = np.zeros_like(pd)
        out[dy:, dx:] = pd[: pd.shape[0] - dy, : pd.shape[1] - dx]
        PILImage.fromarray(out).save(path)
    return write


def cli_cases() -> list[Case]:
    torus = "{meshes}/torus.off"
    rows = [
        ("no-command", [], 2, r"(usage|COMMAND|required)"),
        ("unknown-command", ["teleport"], 2, r"teleport"),
        ("unknown-option", ["skeleton", torus, "--bogus"], 2, r"--bogus"),
        ("missing-positional", ["skeleton"], 2, r"mesh"),
        ("levels-1", ["skeleton", torus, "--levels", "1"], 2, r"levels"),
        ("levels-0", ["skeleton", torus, "--levels", "0"], 2, r"levels"),
        ("levels-text", ["skeleton", torus, "--levels", "many"], 2, r"levels"),
        ("levels-float", ["skeleton", torus, "--levels", "2.5"], 2, r"levels"),
        ("function-unknown", ["skeleton", torus, "--function", "magic"], 2, r"magic"),
        ("min-area-2", ["skeleton", torus, "--min-area-fraction", "2"], 2, r"min-area-fraction|min_area_fraction"),
        ("min-area-nan", ["skeleton", torus, "--min-area-fraction", "nan"], 2, r"min-area-fraction|min_area_fraction"),
        ("root-mode-bad", ["skeleton", torus, "--root-mode", "sideways"], 2, r"sideways"),
        ("k-0", ["query", torus, "--db", "{d}/x.db", "-k", "0"], 2, r"-k"),
        ("k-negative", ["query", torus, "--db", "{d}/x.db", "-k", "-1"], 2, r"-k"),
        ("k-text", ["query", torus, "--db", "{d}/x.db", "-k", "five"], 2, r"-k"),
        ("unmatched-nan", ["match", torus, torus, "--unmatched-cost", "nan"], 2, r"unmatched"),
        ("unmatched-inf", ["match", torus, torus, "--unmatched-cost", "inf"], 2, r"unmatched"),
        ("unmatched-negative", ["match", torus, torus, "--unmatched-cost", "-1"], 2, r"unmatched"),
        ("endpoint-window-negative", ["match", torus, torus, "--endpoint-window", "-1"], 2, r"endpoint"),
        ("method-unknown", ["match", torus, torus, "--method", "vibes"], 2, r"vibes"),
        ("correspondence-unknown", ["match", torus, torus, "--correspondence", "psychic"], 2, r"psychic"),
        ("metric-unknown", ["register", torus, torus, "--metric", "vibes"], 2, r"vibes"),
        ("alpha-0", ["register", torus, torus, "--alpha", "0"], 2, r"alpha"),
        ("alpha-nan", ["register", torus, torus, "--alpha", "nan"], 2, r"alpha"),
        ("seed-text", ["register", torus, torus, "--seed", "lucky"], 2, r"seed"),
        ("slice-text", ["register", torus, torus, "--fixed-slice", "middle"], 2, r"slice"),
        ("workers-0", ["index", torus, "--db", "{d}/x.db", "--workers", "0"], 2, r"workers"),
        ("workers-text", ["index", torus, "--db", "{d}/x.db", "--workers", "all"], 2, r"workers"),
        ("executor-unknown", ["index", torus, "--db", "{d}/x.db", "--executor", "gpu"], 2, r"gpu"),
        ("address-with-local", ["index", torus, "--db", "{d}/x.db", "--address", "tcp://127.0.0.1:8786"], 2,
         r"executor\.address \(--address\) applies only to the dask executor"),
        ("workers-with-address", ["index", torus, "--db", "{d}/x.db", "--executor", "dask", "--address",
                                  "tcp://127.0.0.1:8786", "--workers", "2"], 2, r"executor\.workers .*that cluster decides"),
        ("dask-timeout-negative", ["index", torus, "--db", "{d}/x.db", "--executor", "dask", "--dask-timeout", "-1"], 2,
         r"--dask-timeout: Input should be greater than 0"),
        ("index-no-db", ["index", torus], 2, r"--db"),
        ("out-empty", ["skeleton", torus, "--out", ""], 2, r"--out: an empty path"),
        ("db-empty", ["query", torus, "--db", ""], 2, r"--db: an empty path"),
        ("run-no-config", ["run"], 2, r"config"),
        ("skeleton-out-is-file", ["skeleton", torus, "--out", "{d}/f.txt"], 1,
         r"f\.txt: .*(file is in the way|Not a directory|exists)"),
        ("skeleton-out-proc", ["skeleton", torus, "--out", "/proc/topomatch-out"], 1, r"/proc/topomatch-out"),
        ("evaluate-out-is-file", ["evaluate", "--db", "{db}", "--method", "d2", "--out", "{d}/f.txt/x"], 1, r"f\.txt"),
    ]
    out = []
    for cid, argv, code, message in rows:
        needs = ("db",) if "{db}" in argv else ()
        out.append(Case(f"cli-{cid}", "cli", argv, code, message, {"f.txt": "x"}, needs))
    return out


def database_cases() -> list[Case]:
    torus = "{meshes}/torus.off"
    q = ["query", torus, "--db", "{d}/x.db"]
    e = ["evaluate", "--db", "{d}/x.db"]
    rows = [
        ("query-missing", q, {}, (), r"x\.db: .*(not found|no such|does not exist)"),
        ("query-empty-file", q, {"x.db": b""}, (), r"x\.db: "),
        ("query-text-file", q, {"x.db": "hello, I am not a database\n"}, (), r"x\.db: .*(not a topomatch index|not a database)"),
        ("query-foreign-sqlite", q, {"x.db": lambda p: _sqlite(p, ["CREATE TABLE t(a)"])}, (), r"x\.db: .*not a topomatch index"),
        ("query-directory", ["query", torus, "--db", "{d}/sub"], {"sub/a.txt": "x"}, (), r"sub: "),
        ("evaluate-missing", e, {}, (), r"x\.db: "),
        ("evaluate-text-file", e, {"x.db": "not sqlite"}, (), r"x\.db: "),
        ("evaluate-foreign-sqlite", e, {"x.db": lambda p: _sqlite(p, ["CREATE TABLE shapes(x)"])}, (),
         r"x\.db: .*not a topomatch index"),
        ("index-db-proc", ["index", torus, "--db", "/proc/x.db"], {}, (), r"/proc/x\.db"),
        ("index-db-is-directory", ["index", torus, "--db", "{d}/sub"], {"sub/a.txt": "x"}, (), r"sub: "),
        ("index-foreign-sqlite", ["index", torus, "--db", "{d}/x.db", "--method", "d2"],
         {"x.db": lambda p: _sqlite(p, ["CREATE TABLE t(a)"])}, (), r"x\.db: .*not a topomatch index"),
        ("index-labels-missing", ["index", torus, "--db", "{d}/x.db", "--labels", "{d}/none.csv"], {}, (),
         r"none\.csv: "),
        ("query-device", ["query", torus, "--db", "/dev/zero"], {}, (), r"/dev/zero: not a regular file"),
        ("index-fifo", ["index", torus, "--db", "{d}/fifo", "--method", "d2"], {"fifo": lambda p: os.mkfifo(p)}, (),
         r"fifo: not a regular file"),
        ("evaluate-no-class-of-3", ["evaluate", "--db", "{db}", "--method", "d2"], {}, ("db",),
         r"shared\.db: no class has 3 or more labelled shapes \(largest: 2\)"),
        ("index-labels-conflicting", ["index", torus, "--db", "{d}/x.db", "--labels", "{d}/l.csv", "--method", "d2"],
         {"l.csv": "relative_path,class\ntorus.off,ring\nother.off,x\ntorus.off,donut\n"}, (),
         r"l\.csv: 'torus\.off' has class 'ring' on row 2 and 'donut' on row 4"),
        ("index-labels-malformed", ["index", torus, "--db", "{d}/x.db", "--labels", "{d}/l.csv", "--method", "d2"],
         {"l.csv": "\0\0binary\n"}, (), r"l\.csv: "),
    ]
    out = [Case(f"database-{cid}", "database", argv, 1, message, files, needs) for cid, argv, files, needs, message in rows]
    damaged = [
        ("corrupt-pages", _corrupt_pages, r"(damaged|malformed|corrupt|not a topomatch index)"),
        ("truncated", _truncate_half, r"(damaged|malformed|corrupt|not a topomatch index)"),
        ("pickled-blob", _pickle_blob, r"(pickle|unreadable|damaged|descriptor)"),
        ("nan-descriptor", _descriptor(_nan_first), r"shared\.db: row \d+ .* NaN or infinite"),
        ("short-descriptor", _descriptor(lambda d: d[:-3]), r"shared\.db: row \d+ .* shape \(\d+,\) where most rows of d2 have length 64"),
        ("long-descriptor", _descriptor(lambda d: np.concatenate([d, d])), r"shared\.db: row \d+ .* where most rows of d2 have length 64"),
        ("scalar-descriptor", _descriptor(lambda d: np.array(d.flat[0])), r"shared\.db: row \d+ .* a 0-D array in a row of kind 'vector'"),
        ("number-not-blob", _descriptor(lambda d: float(d.flat[0])), r"shared\.db: row \d+ .* stored as float"),
        ("null-descriptor", _descriptor(lambda d: None), r"shared\.db: row \d+ .*\(NULL\)"),
        ("huge-descriptor", _descriptor(lambda d: b"\x93NUMPY" + b"\0" * (5 * 2**20)), r"shared\.db: row \d+ .* bytes"),
    ]
    for cid, damage, message in damaged:
        for command in ("query", "evaluate"):
            argv = ["query", torus, "--db", "{db}", "--method", "d2"] if command == "query" else [
                "evaluate", "--db", "{db}", "--method", "d2"]
            out.append(Case(f"database-{command}-{cid}", "database", argv, 1, message, {"@db": damage}, ("db",)))
    return out


def cache_cases() -> list[Case]:
    """A finished run whose cache is then damaged: the re-run must recompute and succeed (status 0)."""
    argv = ["run", "{d}/ok.yaml", "--out", "{d}/out", "--no-progress"]
    out = []
    for how in ("truncate", "garbage", "empty", "json", "pickle"):
        out.append(Case(f"cache-{how}", "cache", argv, 0, r"", {"@run": _damage_cache(how)}, ("run",)))
    out.append(Case("cache-dir-is-file", "cache", ["run", "{d}/ok.yaml", "--out", "{d}/out2", "--cache-dir",
                                                   "{d}/ok.off", "--no-progress"], 1, r"ok\.off",
                    {"@run": lambda d: None}, ("run",)))
    return out


def _volume_nii(*, pixdim: tuple[float, float, float] | None = None, orientation: bool = True,
                vox_offset: int | None = None, keep: float = 1.0) -> Callable[[Path], None]:
    """The bundled T1 volume written as an uncompressed .nii, then its header bytes edited as a damaged or
    careless writer leaves them: voxel sizes, no qform / sform, a data offset, or the file cut to ``keep``."""
    def write(path: Path) -> None:
        import nibabel as nib

        src = nib.load(str(ITK / "KmeansTest_T1UCharRaw.nii.gz"))
        nib.save(nib.Nifti1Image(np.asarray(src.dataobj), src.affine), str(path))
        data = bytearray(path.read_bytes())
        if pixdim is not None:
            struct.pack_into("<3f", data, 80, *pixdim)  # pixdim[1..3] of the NIfTI-1 header
        if not orientation:
            struct.pack_into("<hh", data, 252, 0, 0)  # qform_code, sform_code
        if vox_offset is not None:
            struct.pack_into("<f", data, 108, float(vox_offset))
        path.write_bytes(bytes(data[: int(len(data) * keep)]))
    return write


def _nifti_edit(**fields: float) -> Callable[[Path], None]:
    """The bundled T1 volume as an uncompressed .nii with NIfTI-1 header fields set to the given values
    (``scl_slope``, ``qform_code``, ``qoffset_x``, ...), as a careless writer leaves them."""
    offsets = {"scl_slope": (112, "<f"), "scl_inter": (116, "<f"), "qform_code": (252, "<h"), "quatern_b": (256, "<f"),
               "qoffset_x": (268, "<f")}

    def write(path: Path) -> None:
        _volume_nii()(path)
        data = bytearray(path.read_bytes())
        for name, value in fields.items():
            at, fmt = offsets[name]
            struct.pack_into(fmt, data, at, value)
        path.write_bytes(bytes(data))
    return write


def _nifti_gz_claim(shape: tuple[int, ...]) -> Callable[[Path], None]:
    """A 1 KB .nii.gz whose header declares a float64 volume of ``shape`` (hundreds of MB) it does not hold."""
    def write(path: Path) -> None:
        import nibabel as nib

        header = nib.Nifti1Image(np.zeros((2, 2, 2)), np.eye(4)).header
        header.set_data_shape(shape)
        path.write_bytes(gzip.compress(header.binaryblock + b"\0" * 4 + b"\0" * 1000))
    return write


def _metaimage(*, keep: float = 1.0, detached: bool = False) -> Callable[[Path], None]:
    """The bundled T1 volume as MetaImage (.mha, or .mhd + .raw), its pixel data cut to ``keep``."""
    def write(path: Path) -> None:
        import SimpleITK as sitk

        sitk.WriteImage(sitk.ReadImage(str(ITK / "KmeansTest_T1UCharRaw.nii.gz")), str(path))
        target = path.with_suffix(".raw") if detached else path
        data = target.read_bytes()
        target.write_bytes(data[: len(data) - int((1 - keep) * 128 * 128 * 62)])
    return write


def _mha_edit(line: bytes) -> Callable[[Path], None]:
    """The bundled T1 volume as .mha with one header line replaced (matched by its key)."""
    def write(path: Path) -> None:
        _metaimage()(path)
        data = path.read_bytes()
        key = line.split(b"=")[0].strip()
        start = data.index(key)
        path.write_bytes(data[:start] + line + data[data.index(b"\n", start):])
    return write


def _dicom_series(*, skip: int | None = None) -> Callable[[Path], None]:
    """The bundled T1 volume as a DICOM series (one file per slice, positions and orientation set), in the
    folder ``path``; ``skip``: that slice's file left out, as a copy that lost a file leaves it."""
    def write(path: Path) -> None:
        from topomatch.stages.imaging.files import keep_locale

        with keep_locale():  # GDCM sets the process locale to "C" and leaves it (the test process's text I/O)
            _write_series(path)

    def _write_series(path: Path) -> None:
        import SimpleITK as sitk

        path.mkdir(parents=True, exist_ok=True)
        img = sitk.Cast(sitk.RescaleIntensity(sitk.ReadImage(str(ITK / "KmeansTest_T1UCharRaw.nii.gz")), 0, 1000),
                        sitk.sitkInt16)
        d = img.GetDirection()
        writer = sitk.ImageFileWriter()
        writer.KeepOriginalImageUIDOn()
        for k in range(img.GetDepth()):
            if k == skip:
                continue
            piece = img[:, :, k]
            for tag, value in (("0020|000e", "1.2.826.0.1.3680043.2.1125.1.7"), ("0020|000d", "1.2.826.0.1.3680043.2.1125.1"),
                               ("0008|0060", "MR"), ("0020|0013", str(k)),
                               ("0020|0037", "\\".join(map(str, (d[0], d[3], d[6], d[1], d[4], d[7])))),
                               ("0020|0032", "\\".join(map(str, img.TransformIndexToPhysicalPoint((0, 0, k)))))):
                piece.SetMetaData(tag, value)
            writer.SetFileName(str(path / f"slice{k:03d}.dcm"))
            writer.Execute(piece)
    return write


def volume_cases() -> list[Case]:
    """3D inputs whose headers or files lie (the second hardening round: docs/hardening.md)."""
    fixed = "{itk}/KmeansTest_T1UCharRaw.nii.gz"
    cases = [
        ("fifo-volume", {"m.nii.gz": lambda p: os.mkfifo(p)}, r"m\.nii\.gz: not a regular file", 1),
        ("nii-zero-pixdim", {"m.nii": _volume_nii(pixdim=(0.0, 2.0, 3.0))}, r"m\.nii: .*pixdim.* 0, 2, 3", 1),
        ("nii-negative-pixdim", {"m.nii": _volume_nii(pixdim=(2.0, -2.0, 3.0))}, r"m\.nii: .*pixdim.* 2, -2, 3", 1),
        ("nii-nan-pixdim", {"m.nii": _volume_nii(pixdim=(float("nan"), 2.0, 3.0))}, r"m\.nii: .*pixdim.* nan", 1),
        ("nii-no-orientation", {"m.nii": _volume_nii(orientation=False)}, r"m\.nii: .*neither a qform nor an sform",
         None),
        ("nii-truncated-3d", {"m.nii": _volume_nii(keep=0.6)}, r"m\.nii: truncated: the header declares 128 x 128 x 62", 1),
        ("nii-offset-past-end", {"m.nii": _volume_nii(vox_offset=10_000_000)}, r"m\.nii: its data offset .* past the end", 1),
        ("mha-truncated", {"m.mha": _metaimage(keep=0.5)}, r"m\.mha: truncated: .* m\.mha holds", 1),
        ("mhd-raw-truncated", {"m.mhd": _metaimage(keep=0.5, detached=True)}, r"m\.mhd: truncated: .* m\.raw holds", 1),
        ("dicom-missing-slice", {"series": _dicom_series(skip=30)}, r"series: .*not evenly spaced: 6 mm .* 3 mm apart", 1),
        ("nii-vox-offset-zero", {"m.nii": _volume_nii(vox_offset=0)}, r"m\.nii: its data offset \(vox_offset 0\) lies inside", 1),
        ("nii-qoffset-nan", {"m.nii": _nifti_edit(qform_code=1, qoffset_x=float("nan"))}, r"m\.nii: the qform .* not finite", 1),
        ("nii-qoffset-1e20", {"m.nii": _nifti_edit(qform_code=1, qoffset_x=1e20)},
         r"m\.nii: the qform's origin \(qoffset .*\) lies beyond 1e9 mm", 1),
        ("nii-tiny-pixdim", {"m.nii": _volume_nii(pixdim=(1e-30, 1e-30, 1e-30))}, r"m\.nii: pixel spacing 1e-30", 1),
        ("nii-gz-not-gzip", {"m.nii.gz": _png(16, 16)}, r"m\.nii\.gz: cannot read image \(BadGzipFile", 1),
        ("nii-gz-size-claim", {"m.nii.gz": _nifti_gz_claim((464, 464, 464))}, r"m\.nii\.gz: truncated: .* inflates to fewer", 1),
        ("mha-ndims-99", {"m.mha": "ObjectType = Image\nNDims = 99\nDimSize = 4 4 4\nElementType = MET_UCHAR\n"
                                   "ElementDataFile = LOCAL\n" + "x" * 64}, r"m\.mha: .*NDims = '99'", 1),
        ("mha-negative-spacing", {"m.mha": _mha_edit(b"ElementSpacing = -2 2 3")}, r"m\.mha: .*elementspacing = '-2 2 3'", 1),
        ("nrrd-fifo-data", {"m.nhdr": "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 8 8 8\nencoding: raw\n"
                                      "data file: fifo.raw\n\n", "fifo.raw": lambda p: os.mkfifo(p)}, r"m\.nhdr: its data file .*fifo\.raw is not a regular file", 1),
    ]
    out = [Case(f"volume-{cid}", "image", ["register", fixed, "{d}/" + next(iter(files))], code if code is not None
                else 1, message, files) for cid, files, message, code in cases]
    out.append(Case("volume-dicom-series-reads", "image", ["register", fixed, "{d}/series", "--json"], 0,
                    r'"ok": true', {"series": _dicom_series()}))
    out.append(Case("volume-nii-scaled-reads", "image", ["register", fixed, "{d}/m.nii", "--json"], 0, r'"ok": true',
                    {"m.nii": _nifti_edit(scl_slope=0.5, scl_inter=10.0)}))  # scaled voxels: valid, not "truncated"
    out.append(Case("volume-out-over-input", "image", ["register", fixed, "{d}/moving_resampled.nii.gz", "--out", "{d}"],
                    1, r"moving_resampled\.nii\.gz: is one of the registration's input files",
                    {"moving_resampled.nii.gz": lambda p: p.write_bytes((ITK / "KmeansTest_T1UCharRaw.nii.gz").read_bytes())}))
    pd = "{itk}/BrainProtonDensitySlice.png"
    out.append(Case("image-out-target-is-a-folder", "image", ["register", pd, pd, "--out", "{d}/o"], 1,
                    r"o/overlay\.png: is a folder, not a file", {"o/overlay.png/x.txt": "x"}))
    out.append(Case("image-out-long-name", "image", ["register", pd, pd, "--out", "{d}/" + "o" * 250], 0, r"ok"))
    out.append(Case("config-export-folder-parent", "config", ["validate", "{d}/c.yaml"], 2,
                    r"export\.folder: '\.\.' is not a folder of its own",
                    {"c.yaml": "name: e\ninputs: {meshes: ['{bundled}/meshes/torus.off']}\nstages: [load]\n"
                               "reports: [{export: {folder: '..'}}]\n"}))
    out.append(Case("database-labels-fifo", "database", ["index", "{meshes}/torus.off", "--db", "{d}/x.db", "--labels",
                                                          "{d}/l.csv", "--method", "d2"], 1,
                    r"l\.csv: not a regular file", {"l.csv": lambda p: os.mkfifo(p)}))
    out.append(Case("config-fifo", "config", ["run", "{d}/c.yaml"], 1, r"c\.yaml: not a regular file",
                    {"c.yaml": lambda p: os.mkfifo(p)}))
    out.append(Case("config-fifo-input", "config", ["validate", "{d}/c.yaml"], 1, r"m\.nii\.gz: not a regular file",
                    {"m.nii.gz": lambda p: os.mkfifo(p),
                     "c.yaml": "name: fifo\ninputs:\n  pairs:\n    - {fixed: '{d}/m.nii.gz', moving: '{d}/m.nii.gz'}\n"
                               "stages: [load_pair, register]\n"}))
    return out


def all_cases() -> list[Case]:
    cases = (mesh_cases() + config_cases() + image_cases() + volume_cases() + cli_cases() + database_cases()
             + cache_cases())
    ids = [c.id for c in cases]
    assert len(ids) == len(set(ids)), "duplicate case ids"
    return cases


def write_files(case: Case, d: Path, assets: dict[str, Path]) -> None:
    """Write the case's files into ``d`` (and apply damage to copied assets, keys starting with '@')."""
    import shutil

    if "db" in case.needs:
        shutil.copy(assets["db"], d / "shared.db")
    if "run" in case.needs:
        shutil.copytree(assets["run"], d, dirs_exist_ok=True)
    for name, content in case.files.items():
        if name == "@db":
            content(d / "shared.db")
            continue
        if name == "@run":
            content(d)
            continue
        path = d / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if callable(content):
            content(path)
        elif isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content.replace("{d}", str(d)) if name.endswith(".yaml") else content)


def command_line(case: Case, d: Path) -> list[str]:
    """The case's argv with the placeholders filled in."""
    subs = {"{d}": str(d), "{meshes}": str(MESHES), "{itk}": str(ITK), "{db}": str(d / "shared.db")}
    out = []
    for arg in case.argv:
        for key, value in subs.items():
            arg = arg.replace(key, value)
        out.append(arg)
    return out


def make_assets(root: Path, run_command: Callable[[list[str]], None]) -> dict[str, Path]:
    """A small valid index (two bundled meshes, labelled) and a finished run of ``ok.yaml`` with its cache."""
    root.mkdir(parents=True, exist_ok=True)
    meshes = root / "meshes"
    meshes.mkdir(exist_ok=True)
    import shutil

    names = ("torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz", "odedstein_hand_closed.obj.gz")
    for name in names:
        shutil.copy(MESHES / name, meshes / name)
    (meshes / "labels.csv").write_text("relative_path,class\ntorus.off,handles\neight_genus2.off,handles\n"
                                       "odedstein_hand_lowres.obj.gz,hand\nodedstein_hand_closed.obj.gz,hand\n")
    run_command(["index", str(meshes), "--db", str(root / "shared.db"), "--method", "d2",
                 "--labels", str(meshes / "labels.csv"), "--no-progress"])
    run_root = root / "run"
    run_root.mkdir(exist_ok=True)
    (run_root / "ok.off").write_text(OCTAHEDRON)
    cfg = dict(BASE_CONFIG, inputs={"meshes": [str(run_root / "ok.off")]})
    (run_root / "ok.yaml").write_text(_yaml(cfg))
    run_command(["run", str(run_root / "ok.yaml"), "--out", str(run_root / "out"), "--no-progress"])
    return {"db": root / "shared.db", "run": run_root}
