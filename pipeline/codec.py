"""Typed serialisation of stage results, with no pickle: JSON for the structure, ``.npz`` for arrays.

:func:`dumps` turns a result into the bytes of one ``.npz`` archive: every numpy array becomes
an archive member (``a0``, ``a1``, ...) and the rest of the value becomes a JSON document
(member ``__meta__``, UTF-8) with a schema version. :func:`loads` reads it back with
``allow_pickle=False`` and rebuilds only these kinds of values:

- ``None``, bools, ints, floats (NaN and infinities too), strings, bytes, lists, tuples, sets,
  dicts (any keys of these kinds), :class:`pathlib.Path`;
- numpy arrays of numeric, bool or string dtype, and numpy scalars (dtype kept);
- ``scipy.sparse`` CSR / CSC / COO matrices and arrays;
- ``networkx`` graphs (``Graph``, ``DiGraph``, ``MultiGraph``, ``MultiDiGraph``) with their node,
  edge and graph attributes;
- dataclasses, named tuples, enums and pydantic models **of a registered type**: the types that
  the engine found in the scanned stage modules (:func:`register_types`, called by
  :func:`topomatch.pipeline.registry.discover`). A type is named ``module:QualName`` in the
  document, but a name is only looked up in that table, never imported: data can select which
  of the project's own result types to build, nothing else.

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
from pathlib import Path, PurePath
from typing import Any, Iterable

import numpy as np

#: Bump when the document layout changes (older entries become misses).
SCHEMA_VERSION = 1

_TYPES: dict[str, type] = {}


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


def register_types(modules: Iterable[Any]) -> None:
    """Allow the dataclasses, named tuples, enums and pydantic models defined in ``modules``."""
    for module in modules:
        for obj in vars(module).values():
            if (isinstance(obj, type) and obj.__module__ == module.__name__
                    and (dataclasses.is_dataclass(obj) or _is_namedtuple(obj) or issubclass(obj, enum.Enum)
                         or _is_model(obj))):
                _TYPES[type_name(obj)] = obj


def registered(cls: type) -> bool:
    return _TYPES.get(type_name(cls)) is cls


# --------------------------------------------------------------------------- encoding


_GRAPHS = ("Graph", "DiGraph", "MultiGraph", "MultiDiGraph")
_SPARSE_COMPRESSED = ("csr_matrix", "csc_matrix", "csr_array", "csc_array")
_SPARSE_COO = ("coo_matrix", "coo_array")


class _Encoder:
    def __init__(self) -> None:
        self.arrays: list[np.ndarray] = []

    def array(self, a: np.ndarray) -> int:
        if a.dtype.hasobject:
            raise CodecError(f"cannot store an array of Python objects (dtype {a.dtype})")
        self.arrays.append(a)  # np.save keeps the memory order (C or Fortran): downstream BLAS sees the same layout
        return len(self.arrays) - 1

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
            edges = v.edges(keys=True, data=True) if multi else v.edges(data=True)
            return {"$graph": cls.__name__, "graph": self(dict(v.graph)),
                    "nodes": [[self(n), self(dict(d))] for n, d in v.nodes(data=True)],
                    "edges": [[self(e[0]), self(e[1]), *([self(e[2])] if multi else []), self(dict(e[-1]))]
                              for e in edges]}
        if module == "scipy" and cls.__name__ in _SPARSE_COMPRESSED:
            return {"$sparse": cls.__name__, "shape": list(v.shape), "data": self.array(v.data),
                    "indices": self.array(v.indices), "indptr": self.array(v.indptr)}
        if module == "scipy" and cls.__name__ in _SPARSE_COO:
            return {"$sparse": cls.__name__, "shape": list(v.shape), "data": self.array(v.data),
                    "row": self.array(v.row), "col": self.array(v.col)}
        raise CodecError(f"cannot store a value of type {cls.__module__}.{cls.__qualname__}")

    @staticmethod
    def known(cls: type) -> str:
        name = type_name(cls)
        if _TYPES.get(name) is not cls:
            raise CodecError(f"type {name} is not registered (only types of the scanned stage modules are stored)")
        return name


def dumps(value: Any) -> bytes:
    """The ``.npz`` bytes of ``value`` (module docstring). Raises :class:`CodecError`."""
    enc = _Encoder()
    doc = {"schema": SCHEMA_VERSION, "value": enc(value)}
    members = {f"a{i}": a for i, a in enumerate(enc.arrays)}
    members["__meta__"] = np.frombuffer(json.dumps(doc).encode("utf-8"), dtype=np.uint8)
    buf = io.BytesIO()
    np.savez(buf, **members)
    return buf.getvalue()


# --------------------------------------------------------------------------- decoding


class _Decoder:
    def __init__(self, archive) -> None:
        self.archive = archive

    def array(self, i: Any) -> np.ndarray:
        if not isinstance(i, int) or f"a{i}" not in self.archive.files:
            raise CodecError(f"missing array member a{i}")
        return self.archive[f"a{i}"]

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
            for n, d in v["nodes"]:
                G.add_node(_hashable(self(n)), **self(d))
            for e in v["edges"]:
                if G.is_multigraph():
                    G.add_edge(_hashable(self(e[0])), _hashable(self(e[1])), key=_hashable(self(e[2])), **self(e[3]))
                else:
                    G.add_edge(_hashable(self(e[0])), _hashable(self(e[1])), **self(e[2]))
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

    @staticmethod
    def known(name: Any, base: type | None) -> type:
        cls = _TYPES.get(name) if isinstance(name, str) else None
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
            meta = archive["__meta__"]
            if meta.dtype != np.uint8 or meta.ndim != 1:
                raise CodecError("bad __meta__ member")
            doc = json.loads(meta.tobytes().decode("utf-8"))
            if not isinstance(doc, dict) or doc.get("schema") != SCHEMA_VERSION:
                raise CodecError(f"schema {doc.get('schema') if isinstance(doc, dict) else '?'} is not "
                                 f"{SCHEMA_VERSION}")
            return _Decoder(archive)(doc["value"])
    except CodecError:
        raise
    except RecursionError:
        raise CodecError("document nested too deeply") from None
    except Exception as exc:  # a damaged archive, bad JSON, a constructor that rejects the fields, ...
        raise CodecError(f"{type(exc).__name__}: {exc}") from None
