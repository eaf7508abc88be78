"""The stage cache stores typed data, never pickle: every stage's result survives it unchanged, and a
damaged, foreign or crafted entry is a miss with a warning, never code execution or an aborted run."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import stat
from importlib.metadata import entry_points

import networkx as nx
import numpy as np
import pytest
import scipy.sparse as sp

from topomatch.pipeline import codec
from topomatch.pipeline.cache import Cache, CacheWarning
from topomatch.pipeline.config import build_experiment
from topomatch.pipeline.item import run_item
from topomatch.pipeline.registry import GROUPS, discover
from topomatch.pipeline.runner import run_experiment
from tests_paths import BUNDLED_MESHES, ITK_DIR


def same(a, b, path="value") -> None:
    """Assert that two values are equal in type and content (arrays: dtype, shape, memory order, bits)."""
    assert type(a) is type(b), f"{path}: {type(a).__name__} vs {type(b).__name__}"
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, path
        assert a.flags.f_contiguous == b.flags.f_contiguous or a.ndim < 2, f"{path}: memory order"
        np.testing.assert_array_equal(a, b, err_msg=path)
    elif isinstance(a, float):
        assert a == b or (np.isnan(a) and np.isnan(b)), path
    elif sp.issparse(a):
        assert a.format == b.format and a.shape == b.shape and (a != b).nnz == 0, path
    elif isinstance(a, nx.Graph):
        assert list(a.nodes) == list(b.nodes), path
        for n in a.nodes:
            same(dict(a.nodes[n]), dict(b.nodes[n]), f"{path}.nodes[{n}]")
        ea = list(a.edges(keys=True, data=True) if a.is_multigraph() else a.edges(data=True))
        eb = list(b.edges(keys=True, data=True) if b.is_multigraph() else b.edges(data=True))
        assert [e[:-1] for e in ea] == [e[:-1] for e in eb], path
        for x, y in zip(ea, eb):
            same(x[-1], y[-1], f"{path}.edges{x[:-1]}")
    elif dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, dict):
        assert list(a) == list(b), path
        for k in a:
            same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{path}[{i}]")
    else:
        assert a == b, path


MESH_CHAIN = [
    "load", {"clean": {"components": "largest"}}, "measures",
    {"noise": {"sigma": 0.001, "relative_to": "bbox_diagonal", "seed": 1}},
    {"transform": {"axis": [1.0, 0.0, 0.0], "angle_deg": 30.0, "scale": 2.0}},
    {"decimate": {"ratio": 0.5}}, {"decimate_crosscheck": {"ratio": 0.5}}, {"clean": {"components": "largest"}},
    "laplacian", "fiedler", {"morse": {"function": "mixture"}}, "level_sets", "reeb_graph", "prune",
    "endpoint_descriptor", "libigl_reference", "fill_holes", {"spectrum": {"k": 20}}, "hks", "gps",
    {"shapedna_of_spectrum": {"k": 10}},
    "endpoint_hks_descriptor",
    "d2", "spherical_harmonics", {"shapedna": {"k": 10}}, "sdgdm", {"light_field": {"light_fields": 2}},
]
IMAGE_CHAIN = [
    "load_pair", {"misalign_pair": {"theta": [4.0, 3.0, -2.0]}},
    {"register": {"schedule": [{"spacing": 2.0, "iterations": 20}]}}, "evaluate",
    "register_sitk", {"landscape": {"points": 5}},
]

VOLUME = ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz"
FAST_3D = {"schedule": [{"spacing": 8.0, "iterations": 10, "samples": 2000}], "start": {"steps": 0},
           "check": {"search": False}}
VOLUME_CHAIN = [
    "load_image", {"misalign": {"index": 1, "seed": 4, "contrast": "t2_like", "crop": 0.7}},
    {"register": FAST_3D}, "evaluate",
    {"register_sitk_3d": {"shrink": [4], "smoothing": [2.0], "iterations": 5}},
]
VOLUME_PAIR_CHAIN = ["load_pair", {"register": FAST_3D}, "evaluate"]


def _items(tmp_path):
    meshes = build_experiment({"name": "all-mesh-stages", "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off")]},
                               "stages": MESH_CHAIN, "executor": {"workers": 1}})
    images = build_experiment({"name": "all-image-stages", "inputs": {"pairs": [
        {"fixed": str(ITK_DIR / "BrainProtonDensitySlice.png"), "moving": str(ITK_DIR / "BrainT1Slice.png"),
         "truth": {"tx": 0.0, "ty": 0.0, "angle": 0.0}}]},
        "stages": IMAGE_CHAIN, "executor": {"workers": 1}})
    volumes = build_experiment({"name": "all-volume-stages", "inputs": {"images": [str(VOLUME)]},
                                "stages": VOLUME_CHAIN, "executor": {"workers": 1}})
    volume_pairs = build_experiment({"name": "volume-pair-stages", "inputs": {"pairs": [
        {"fixed": str(VOLUME), "moving": str(VOLUME), "truth": {"tx": 0.0}}]}, "stages": VOLUME_PAIR_CHAIN,
        "executor": {"workers": 1}})
    return meshes.items() + images.items() + volumes.items() + volume_pairs.items()


def _nan_equal(a: dict, b: dict) -> bool:
    """Rows equal, a NaN equal to a NaN (a failed reference registration reports NaN metrics)."""
    def same(x, y):
        return x == y or (isinstance(x, float) and isinstance(y, float) and np.isnan(x) and np.isnan(y))
    return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)


@pytest.mark.slow
def test_every_stage_result_survives_the_cache(tmp_path):
    stages_seen = set()
    for item in _items(tmp_path):
        first = run_item(item, str(tmp_path / "cache"))
        assert first.ok, first.error
        assert not any(first.cache_hits.values())
        again = run_item(item, str(tmp_path / "cache"))
        assert all(again.cache_hits.values()), again.cache_hits
        for label, result in first.results.items():
            same(result, again.results[label], label)
            stages_seen.add(label.split("#")[0])
        assert _nan_equal(again.row(), first.row())
    stages = discover()
    declared = {ep.name for ep in entry_points(group=GROUPS["stage"])}  # not those another test registers at run time
    untested = {n for n in stages if n in declared and n not in stages_seen and not n.startswith("test_")}
    # the stages whose inputs these chains cannot provide (a single image, a pair stage of its own)
    assert untested <= {"load_image", "misalign"}, untested


def test_basic_values_round_trip():
    G = nx.MultiGraph(name="g")
    G.add_node("root", pos=np.array([0.0, 1, 2]))
    G.add_node(np.int64(3), members=np.arange(4), band=2)
    G.add_edge("root", np.int64(3), level=-1)
    G.add_edge("root", np.int64(3), level=-1)
    value = {
        "none": None, "t": True, "i": 7, "big": 2**70, "f": 1.5, "nan": float("nan"), "inf": -float("inf"),
        "s": "é", "b": b"\x00\x01", "tuple": (1, (2, 3)), "set": {1, 2}, "frozen": frozenset({"a"}),
        (1, "k"): "tuple key", 3: "int key", "np": [np.float32(1.5), np.int16(-3), np.bool_(True), np.str_("x")],
        "arrays": [np.zeros((0, 3)), np.asfortranarray(np.arange(6.0).reshape(2, 3)), np.array(["a", "bc"]),
                   np.array(5.0), np.arange(10)[::2]],
        "sparse": [sp.csr_matrix(np.eye(3)), sp.csc_matrix(np.eye(2)), sp.coo_matrix(np.eye(2))],
        "graph": G, "digraph": nx.DiGraph([(1, 2)]),
    }
    back = codec.loads(codec.dumps(value))
    same(value["graph"], back["graph"])
    for k in value:
        if k != "graph":
            same(value[k] if k != "arrays" else [np.asarray(a) for a in value[k]], back[k], repr(k))


def test_unregistered_types_are_not_written():
    @dataclasses.dataclass
    class Local:
        x: int

    with pytest.raises(codec.CodecError, match="not registered"):
        codec.dumps(Local(1))
    with pytest.raises(codec.CodecError, match="Python objects"):
        codec.dumps(np.array([object()]))
    with pytest.raises(codec.CodecError, match="cannot store"):
        codec.dumps(lambda: 0)


def _entry(doc: dict | str, blob: np.ndarray | None = None) -> bytes:
    text = doc if isinstance(doc, str) else json.dumps(doc)
    buf = io.BytesIO()
    np.savez(buf, __meta__=np.frombuffer(text.encode(), dtype=np.uint8),
             __blob__=np.zeros(64, dtype=np.uint8) if blob is None else blob)
    return buf.getvalue()


CRAFTED = {
    "pickle in the array blob": lambda: _entry({"schema": 2, "value": {"$array": 0}, "arrays": [["|O", [1], False, 0, 8]]},
                                               np.array([print], dtype=object)),
    "an object dtype in the array table": lambda: _entry({"schema": 2, "value": {"$array": 0},
                                                         "arrays": [["|O", [1], False, 0, 8]]}),
    "an array beyond the blob": lambda: _entry({"schema": 2, "value": {"$array": 0},
                                                "arrays": [["<f8", [100], False, 0, 800]]}),
    "a raw pickle": lambda: b"\x80\x04\x95" + b"cos\nsystem\n(S'touch /tmp/pwned'\ntR.",
    "an unknown type name": lambda: _entry({"schema": 2, "value": {"$dataclass": "os:system", "fields": {}},
                                            "arrays": []}),
    "a dataclass with other fields": lambda: _entry({"schema": 2, "value": {
        "$dataclass": "topomatch.stages.retrieval.fusion:Fusion", "fields": {"x": 1}}, "arrays": []}),
    "another schema": lambda: _entry({"schema": 99, "value": 1}),
    "a truncated archive": lambda: _entry({"schema": 2, "value": 1, "arrays": []})[:40],
    "a deeply nested document": lambda: _entry('{"schema": 2, "arrays": [], "value": ' + "[" * 100000 + "]" * 100000
                                               + "}"),
}


@pytest.mark.parametrize("name", sorted(CRAFTED))
def test_crafted_entry_is_a_miss_and_runs_nothing(name, tmp_path):
    discover()
    cache = Cache(tmp_path)
    key = "ab" + "0" * 62
    (tmp_path / "ab").mkdir()
    (tmp_path / "ab" / f"{key}.npz").write_bytes(CRAFTED[name]())
    with pytest.warns(CacheWarning, match="unusable"):
        assert cache.get(key) == (False, None)
    assert not os.path.exists("/tmp/pwned")


def test_crafted_entries_in_a_run_are_recomputed(small_config, tmp_path):
    """Every entry of a run's cache replaced by a valid entry of a type no stage of the chain returns
    (here a retrieval descriptor): the run warns, recomputes, overwrites and produces the same tables."""
    from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult

    small_config["sweep"] = {}
    first = run_experiment(build_experiment(small_config), out_root=tmp_path / "runs", progress=False)
    entries = sorted((tmp_path / "runs" / ".cache").rglob("*.npz"))
    assert entries
    foreign = codec.dumps(DescriptorResult(Descriptor("vector", np.zeros(3))))
    for path in entries:
        path.write_bytes(foreign)
    with pytest.warns(CacheWarning):
        again = run_experiment(build_experiment(small_config), out_root=tmp_path / "runs", progress=False)
    assert not again.failed
    assert [r.row() for r in again.items] == [r.row() for r in first.items]
    third = run_experiment(build_experiment(small_config), out_root=tmp_path / "runs", progress=False)
    assert all(all(r.cache_hits.values()) for r in third.items)  # the bad entries were overwritten


def test_outputs_are_readable_by_the_group(small_config, tmp_path):
    small_config["sweep"] = {}
    outcome = run_experiment(build_experiment(small_config), out_root=tmp_path / "runs", progress=False)
    umask = os.umask(0)
    os.umask(umask)
    files = [outcome.run_dir / "index.html", outcome.run_dir / "tables" / "results.csv",
             *sorted((tmp_path / "runs" / ".cache").rglob("*.npz"))]
    for path in files:
        assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask, path
