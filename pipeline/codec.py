"""Typed serialisation of stage results, with no pickle: JSON for the structure, ``.npz`` for arrays.

:func:`dumps` turns a result into the bytes of one ``.npz`` archive of two members: ``__blob__``,
the raw bytes of every numpy array of the value one after the other (16-byte aligned; a skeleton
holds hundreds of small arrays, and one member each made loading 13x slower than pickle), and
``__meta__``, a UTF-8 JSON document with a schema version, the value's structure and each array's
dtype, shape, memory order and place in the blob. :func:`loads` reads it back with
``allow_pickle=False`` and rebuilds only these kinds of values:

- ``None``, bools, ints, floats (NaN and infinities too), strings, bytes, lists, tuples, sets,
  dicts (any keys of these kinds), :class:`pathlib.Path`;
- numpy arrays of numeric, bool or string dtype, and numpy scalars (dtype kept);
- ``scipy.sparse`` CSR / CSC / COO matrices and arrays;
- ``networkx`` graphs (``Graph``, ``DiGraph``, ``MultiGraph``, ``MultiDiGraph``) with their node,
  edge and graph attributes, stored by column: the node ids, each node attribute, the edge ends,
  keys and each edge attribute as one array where the values allow it (numbers of one type,
  arrays of one shape, 1-D arrays of one dtype concatenated), so a Reeb graph of hundreds of
  nodes is a dozen arrays, not hundreds of JSON objects;
- dataclasses, named tuples, enums and pydantic models **of an allowed package**: defined in
  ``topomatch.stages``, in the package of a stage or report that a distribution declares as an
  entry point, or in a module registered explicitly (:func:`allow_packages`). A type is named ``module:QualName`` in the
  document; on reading, the module must already be imported (it is, when the stage that returns
  the type is in the chain): a name is looked up, never imported, so data can select which of
  the project's own result types to build, nothing else.

Anything else cannot be written (:class:`CodecError`: the runner then keeps the result in memory
and does not cache it). A document of another schema version, a damaged archive, an unknown
type name or a dataclass whose fields changed is a :class:`CodecError` on load; the cache counts
it as a miss.
"""

from __future__ import annotations

import base64
import dataclasses
import enum
import io
import json
import math
import sys
from pathlib import Path, PurePath
from typing import Any

import numpy as np

#: Bump when the document layout changes (older entries become misses).
SCHEMA_VERSION = 2

#: Alignment of the arrays in the blob (bytes).
_ALIGN = 16

_TYPES: dict[str, type] = {}
_ALLOWED: set[str] = set()  # packages (and modules) whose types may be stored


class CodecError(ValueError):
    """A value that cannot be written, or bytes that are not a valid, known document."""


def type_name(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def _is_namedtuple(cls: type) -> bool:
    return isinstance(cls, type) and issubclass(cls, tuple) and hasattr(cls, "_fields")


def _is_model(cls: type) -> bool:
    try:
        from pydantic import BaseModel
    except ImportError:  # pragma: no cover - pydantic is a dependency
        return False
    return isinstance(cls, type) and issubclass(cls, BaseModel)


def allow_packages(names) -> None:
    """Allow the storable types defined in these packages (and their sub-packages) or modules."""
    _ALLOWED.update(names)


def _storable(obj: Any) -> bool:
    return isinstance(obj, type) and (dataclasses.is_dataclass(obj) or _is_namedtuple(obj)
                                      or issubclass(obj, enum.Enum) or _is_model(obj))


def _lookup(name: Any) -> type | None:
    """The storable class ``module:QualName`` if its module is allowed and already imported."""
    cls = _TYPES.get(name) if isinstance(name, str) else None
    if cls is not None or not isinstance(name, str) or ":" not in name:
        return cls
    module_name, qualname = name.split(":", 1)
    if not any(module_name == p or module_name.startswith(p + ".") for p in _ALLOWED) or "<" in qualname:
        return None
    obj = sys.modules.get(module_name)  # never imported here
    for part in qualname.split("."):
        obj = getattr(obj, part, None) if obj is not None else None
    if _storable(obj) and obj.__module__ == module_name and obj.__qualname__ == qualname:
        _TYPES[name] = obj
        return obj
    return None


def registered(cls: type) -> bool:
    return _lookup(type_name(cls)) is cls


# --------------------------------------------------------------------------- encoding


_GRAPHS = ("Graph", "DiGraph", "MultiGraph", "MultiDiGraph")
_SPARSE_COMPRESSED = ("csr_matrix", "csc_matrix", "csr_array", "csc_array")
_SPARSE_COO = ("coo_matrix", "coo_array")


class _Encoder:
    def __init__(self) -> None:
        self.arrays: list[np.ndarray] = []

    def array(self, a: np.ndarray) -> int:
        if a.dtype.hasobject or a.dtype.fields is not None:
            raise CodecError(f"cannot store an array of Python objects or records (dtype {a.dtype})")
        self.arrays.append(a)
        return len(self.arrays) - 1

    def blob(self) -> tuple[bytes, list[list]]:
        """The arrays' bytes, each in its own memory order (C, or Fortran for an F-contiguous array,
        so that downstream BLAS sees the same layout), and their [dtype, shape, fortran, offset, nbytes]."""
        parts, table, offset = [], [], 0
        for a in self.arrays:
            fortran = a.ndim > 1 and a.flags.f_contiguous and not a.flags.c_contiguous
            raw = (np.asfortranarray(a) if fortran else np.ascontiguousarray(a)).tobytes(order="F" if fortran else "C")
            pad = -offset % _ALIGN
            parts += [b"\0" * pad, raw]
            offset += pad
            table.append([a.dtype.str, list(a.shape), fortran, offset, len(raw)])
            offset += len(raw)
        return b"".join(parts), table

    def __call__(self, v: Any) -> Any:  # noqa: C901 - one branch per kind of value
        if v is None or type(v) in (bool, int, float, str):  # exact types: numpy's subclasses keep their dtype
            return v
        if isinstance(v, np.ndarray):
            return {"$array": self.array(v)}
        if isinstance(v, np.generic):
            return {"$scalar": v.dtype.str, "v": v.item() if v.dtype.kind != "c" else [v.real, v.imag]}
        if isinstance(v, bytes):
            return {"$bytes": base64.b64encode(v).decode("ascii")}
        if isinstance(v, PurePath):
            return {"$path": str(v)}
        cls = type(v)
        if isinstance(v, enum.Enum):
            return {"$enum": self.known(cls), "v": self(v.value)}
        if dataclasses.is_dataclass(v):
            fields = {f.name: self(getattr(v, f.name)) for f in dataclasses.fields(v) if f.init}
            return {"$dataclass": self.known(cls), "fields": fields}
        if _is_namedtuple(cls):
            return {"$namedtuple": self.known(cls), "items": [self(x) for x in v]}
        if _is_model(cls):
            return {"$model": self.known(cls), "data": v.model_dump(mode="json")}
        if cls in (list, tuple, set, frozenset):
            return {"$" + cls.__name__: [self(x) for x in v]} if cls is not list else [self(x) for x in v]
        if cls is dict:
            return {"$dict": [[self(k), self(x)] for k, x in v.items()]}
        module = cls.__module__.split(".")[0]
        if module == "networkx" and cls.__name__ in _GRAPHS:
            multi = v.is_multigraph()
            nodes = list(v.nodes(data=True))
            edges = list(v.edges(keys=True, data=True) if multi else v.edges(data=True))
            out = {"$graph": cls.__name__, "graph": self(dict(v.graph)),
                   "nodes": self.column([n for n, _ in nodes]), "node_attrs": self.records([d for _, d in nodes]),
                   "u": self.column([e[0] for e in edges]), "v": self.column([e[1] for e in edges]),
                   "edge_attrs": self.records([e[-1] for e in edges])}
            if multi:
                out["keys"] = self.column([e[2] for e in edges])
            return out
        if module == "scipy" and cls.__name__ in _SPARSE_COMPRESSED:
            return {"$sparse": cls.__name__, "shape": list(v.shape), "data": self.array(v.data),
                    "indices": self.array(v.indices), "indptr": self.array(v.indptr)}
        if module == "scipy" and cls.__name__ in _SPARSE_COO:
            return {"$sparse": cls.__name__, "shape": list(v.shape), "data": self.array(v.data),
                    "row": self.array(v.row), "col": self.array(v.col)}
        raise CodecError(f"cannot store a value of type {cls.__module__}.{cls.__qualname__}")

    def column(self, values: list) -> dict:
        """A list of values as one array when they allow it (module docstring of the graph layout):
        numpy scalars of one dtype, Python floats / ints / bools, arrays of one shape and dtype
        (stacked), 1-D arrays of one dtype (concatenated, with their lengths); else one by one."""
        kinds = {type(x) for x in values}
        if len(kinds) == 1 and values:
            kind = next(iter(kinds))
            if kind in (float, bool) or (kind is int and all(-2**63 <= x < 2**63 for x in values)):
                return {"py": kind.__name__, "a": self.array(np.array(values, dtype={float: np.float64, int: np.int64,
                                                                                      bool: np.bool_}[kind]))}
            if issubclass(kind, np.generic) and len({x.dtype for x in values}) == 1 and kind is not np.object_:
                return {"np": self.array(np.array(values, dtype=values[0].dtype))}
            if kind is np.ndarray and len({x.dtype for x in values}) == 1 and not values[0].dtype.hasobject:
                if len({x.shape for x in values}) == 1 and values[0].ndim >= 1:
                    return {"stack": self.array(np.stack(values))}
                if all(x.ndim == 1 for x in values):
                    return {"ragged": self.array(np.concatenate(values)),
                            "lengths": self.array(np.array([len(x) for x in values], dtype=np.int64))}
        return {"list": [self(x) for x in values]}

    def records(self, dicts: list[dict]) -> list:
        """A list of attribute dicts as columns: [[key, column or None where a record lacks the key]]."""
        keys = list(dict.fromkeys(k for d in dicts for k in d))
        out = []
        for key in keys:
            present = [key in d for d in dicts]
            values = [d[key] for d in dicts if key in d]
            out.append([self(key), self.column(values), None if all(present) else present])
        return out

    @staticmethod
    def known(cls: type) -> str:
        name = type_name(cls)
        if _lookup(name) is not cls:
            raise CodecError(f"type {name} is not registered (only types of the stage packages are stored)")
        return name


def dumps(value: Any) -> bytes:
    """The ``.npz`` bytes of ``value`` (module docstring). Raises :class:`CodecError`."""
    enc = _Encoder()
    doc = {"schema": SCHEMA_VERSION, "value": enc(value)}
    blob, doc["arrays"] = enc.blob()
    buf = io.BytesIO()
    np.savez(buf, __meta__=np.frombuffer(json.dumps(doc).encode("utf-8"), dtype=np.uint8),
             __blob__=np.frombuffer(blob, dtype=np.uint8))
    return buf.getvalue()


# --------------------------------------------------------------------------- decoding


class _Decoder:
    def __init__(self, blob: np.ndarray, table: Any) -> None:
        if blob.dtype != np.uint8 or blob.ndim != 1 or not isinstance(table, list):
            raise CodecError("bad array blob")
        self.blob, self.table = blob, table

    def array(self, i: Any) -> np.ndarray:
        if not isinstance(i, int) or not 0 <= i < len(self.table):
            raise CodecError(f"no array {i!r}")
        dtype_str, shape, fortran, offset, nbytes = self.table[i]
        dtype = np.dtype(dtype_str)
        if dtype.hasobject or dtype.fields is not None:
            raise CodecError(f"array {i}: dtype {dtype_str} is not allowed")
        count = math.prod(shape)
        if count * dtype.itemsize != nbytes or offset < 0 or offset + nbytes > self.blob.size:
            raise CodecError(f"array {i}: {nbytes} bytes at {offset} do not hold {shape} of {dtype_str}")
        flat = np.frombuffer(self.blob, dtype=dtype, count=count, offset=offset)
        return flat.reshape(shape, order="F" if fortran else "C").copy(order="K")

    def __call__(self, v: Any) -> Any:  # noqa: C901
        if v is None or isinstance(v, (bool, int, float, str)):
            return v
        if isinstance(v, list):
            return [self(x) for x in v]
        if not isinstance(v, dict) or len(v) == 0:
            raise CodecError(f"unexpected value {str(v)[:80]!r}")
        tag = next(iter(v))
        if tag == "$array":
            return self.array(v["$array"])
        if tag == "$scalar":
            dtype = np.dtype(v["$scalar"])
            if dtype.hasobject:
                raise CodecError("object scalar")
            x = v["v"]
            return dtype.type(complex(*x) if dtype.kind == "c" else x)
        if tag == "$bytes":
            return base64.b64decode(v["$bytes"])
        if tag == "$path":
            return Path(v["$path"])
        if tag in ("$tuple", "$set", "$frozenset"):
            return {"$tuple": tuple, "$set": set, "$frozenset": frozenset}[tag](self(x) for x in v[tag])
        if tag == "$dict":
            return {_hashable(self(k)): self(x) for k, x in v["$dict"]}
        if tag == "$enum":
            return self.known(v["$enum"], enum.Enum)(self(v["v"]))
        if tag == "$dataclass":
            cls = self.known(v["$dataclass"], None)
            if not dataclasses.is_dataclass(cls):
                raise CodecError(f"{v['$dataclass']} is not a dataclass")
            expected = {f.name for f in dataclasses.fields(cls) if f.init}
            got = v["fields"]
            if not isinstance(got, dict) or set(got) != expected:
                raise CodecError(f"{v['$dataclass']}: stored fields {sorted(got) if isinstance(got, dict) else got} "
                                 f"differ from the class's {sorted(expected)}")
            return cls(**{k: self(x) for k, x in got.items()})
        if tag == "$namedtuple":
            cls = self.known(v["$namedtuple"], tuple)
            return cls(*[self(x) for x in v["items"]])
        if tag == "$model":
            cls = self.known(v["$model"], None)
            if not _is_model(cls):
                raise CodecError(f"{v['$model']} is not a model")
            return cls.model_validate_json(json.dumps(v["data"]), strict=True)
        if tag == "$graph":
            import networkx as nx

            if v["$graph"] not in _GRAPHS:
                raise CodecError(f"unknown graph class {v['$graph']!r}")
            G = getattr(nx, v["$graph"])()
            G.graph.update(self(v["graph"]))
            nodes = [_hashable(n) for n in self.column(v["nodes"])]
            G.add_nodes_from(zip(nodes, self.records(v["node_attrs"], len(nodes))))
            u, w = self.column(v["u"]), self.column(v["v"])
            attrs = self.records(v["edge_attrs"], len(u))
            if len(w) != len(u):
                raise CodecError("edge columns of different lengths")
            if G.is_multigraph():
                keys = self.column(v["keys"])
                G.add_edges_from((_hashable(a), _hashable(b), _hashable(k), d) for a, b, k, d in zip(u, w, keys, attrs))
            else:
                G.add_edges_from((_hashable(a), _hashable(b), d) for a, b, d in zip(u, w, attrs))
            return G
        if tag == "$sparse":
            import scipy.sparse as sp

            name = v["$sparse"]
            if name not in _SPARSE_COMPRESSED + _SPARSE_COO:
                raise CodecError(f"unknown sparse class {name!r}")
            shape = tuple(v["shape"])
            if name in _SPARSE_COO:
                return getattr(sp, name)((self.array(v["data"]), (self.array(v["row"]), self.array(v["col"]))),
                                         shape=shape)
            return getattr(sp, name)((self.array(v["data"]), self.array(v["indices"]), self.array(v["indptr"])),
                                     shape=shape)
        raise CodecError(f"unknown tag {tag!r}")

    def column(self, spec: Any) -> list:
        """The values of an encoded column (see :meth:`_Encoder.column`)."""
        if not isinstance(spec, dict) or len(spec) == 0:
            raise CodecError("bad column")
        if "list" in spec:
            return [self(x) for x in spec["list"]]
        if "py" in spec:
            if spec["py"] not in ("float", "int", "bool"):
                raise CodecError(f"bad column kind {spec['py']!r}")
            return self.array(spec["a"]).tolist()
        if "np" in spec:
            return list(self.array(spec["np"]))
        if "stack" in spec:
            return [x.copy() for x in self.array(spec["stack"])]
        if "ragged" in spec:
            data, lengths = self.array(spec["ragged"]), self.array(spec["lengths"])
            if lengths.dtype != np.int64 or lengths.ndim != 1 or lengths.sum() != data.size or (lengths < 0).any():
                raise CodecError("bad ragged column")
            return [x.copy() for x in np.split(data, np.cumsum(lengths)[:-1])] if lengths.size else []
        raise CodecError(f"bad column {sorted(spec)}")

    def records(self, spec: Any, n: int) -> list[dict]:
        """``n`` attribute dicts from their encoded columns (see :meth:`_Encoder.records`)."""
        out: list[dict] = [{} for _ in range(n)]
        for key, column, present in spec:
            key, values = _hashable(self(key)), self.column(column)
            rows = range(n) if present is None else [i for i, p in enumerate(present) if p]
            if len(values) != len(rows) or (present is not None and len(present) != n):
                raise CodecError(f"column {key!r} does not match {n} records")
            for i, value in zip(rows, values):
                out[i][key] = value
        return out

    @staticmethod
    def known(name: Any, base: type | None) -> type:
        cls = _lookup(name)
        if cls is None or (base is not None and not issubclass(cls, base)):
            raise CodecError(f"unknown type {name!r}")
        return cls


def _hashable(x: Any) -> Any:
    if isinstance(x, list):
        raise CodecError("a list cannot be a dict key or a node")
    return x


def loads(data: bytes) -> Any:
    """Rebuild the value written by :func:`dumps`. Raises :class:`CodecError` for anything invalid."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            meta, blob = archive["__meta__"], archive["__blob__"]
        if meta.dtype != np.uint8 or meta.ndim != 1:
            raise CodecError("bad __meta__ member")
        doc = json.loads(meta.tobytes().decode("utf-8"))
        if not isinstance(doc, dict) or doc.get("schema") != SCHEMA_VERSION:
            raise CodecError(f"schema {doc.get('schema') if isinstance(doc, dict) else '?'} is not {SCHEMA_VERSION}")
        return _Decoder(blob, doc.get("arrays"))(doc["value"])
    except CodecError:
        raise
    except RecursionError:
        raise CodecError("document nested too deeply") from None
    except Exception as exc:  # a damaged archive, bad JSON, a constructor that rejects the fields, ...
        raise CodecError(f"{type(exc).__name__}: {exc}") from None
