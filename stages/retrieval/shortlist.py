"""Approximate-nearest-neighbour shortlist for large indexes, then the exact fused ranking on it.

A fused query against n shapes needs every part's dissimilarities to all n shapes, and the
database's (n, n) part matrices for the scales, the screening and the re-ranking: fine for
thousands of shapes, impossible for 100,000. For a large index:

1. **Scales and screening from a sample**: each part's median dissimilarity and the parts'
   neighbour agreement (:func:`topomatch.stages.retrieval.fusion.decide`) are computed on a fixed,
   seeded sample of ``SAMPLE`` database shapes (:func:`sample_rows`), once per index.
2. **Shortlist**: the kept vector parts (hks, shapedna, d2, sh), each divided by its scale and
   concatenated (:func:`embedding`, float32), go into an HNSW graph (usearch; Malkov and
   Yashunin, IEEE TPAMI 2020) with squared-Euclidean distance; a query takes its ``count``
   approximate nearest neighbours there.
3. **Exact ranking on the shortlist**: every kept part (the skeleton's endpoint matching too)
   compares the query with the shortlisted shapes only, and the parts are fused exactly as the
   method fuses them (scales, order weights), without manifold ranking (which needs the whole
   collection's graph).

The shortlist misses a shape only if the vector parts' concatenation ranks it beyond ``count``;
``benchmarks/retrieval_large.py`` measures recall@10 against the exact fused ranking over the
whole index. The graph is persisted beside the SQLite index (``<db>.ann`` + ``<db>.ann.json``) and
updated incrementally by ``topomatch index``.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Database shapes whose part matrices give the scales and the screening of a large index.
SAMPLE = 1000

#: Indexes with at least this many shapes rank a fused query through the shortlist.
LARGE_INDEX = 5000

#: Shortlist length per query (at least 20 times the results asked for). Chosen on the tuning queries
#: of ``benchmarks/retrieval_large.py --query-seed 1`` (the smallest length with recall@10 1.0 there;
#: with the agreement-weighted default fusion 300 gave 0.968, 800 0.995, 1200 1.000) and reported on
#: other queries (docs/speed.md).
SHORTLIST = 1200


def shape_key(path: str) -> int:
    """A stable 63-bit key of a shape's path (the graph's label of that shape)."""
    return int.from_bytes(hashlib.sha1(path.encode()).digest()[:8], "little") >> 1


def sample_rows(n: int, size: int = SAMPLE, seed: int = 0) -> np.ndarray:
    """(min(n, size),) sorted row indices of a fixed, seeded sample of a database of ``n`` shapes."""
    if n <= size:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size, replace=False))


def embedding(vectors: dict[str, np.ndarray], scales: dict[str, float]) -> np.ndarray:
    """(n, D) float32: the vector parts' descriptors (n, d_p), each divided by its scale, side by side."""
    return np.hstack([np.asarray(vectors[p], dtype=np.float64) / scales[p] for p in sorted(vectors)]).astype(np.float32)


def row_digests(vectors: dict[str, np.ndarray]) -> np.ndarray:
    """(n,) uint64 digests of each shape's raw vector parts (sorted by part; not scaled): what the graph holds
    of a shape, so that a graph can be checked against the index rows it was built from."""
    stacked = np.hstack([np.ascontiguousarray(vectors[p], dtype=np.float64) for p in sorted(vectors)])
    return np.array([int.from_bytes(hashlib.blake2b(row.tobytes(), digest_size=8).digest(), "little")
                     for row in stacked], dtype=np.uint64)


def _record_digest(record: dict) -> str:
    """SHA-256 of a shortlist record without its own digest field (canonical JSON)."""
    body = {k: v for k, v in record.items() if k != "record_sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()


@dataclass
class Shortlist:
    """An HNSW graph over the embeddings of an index's shapes, keyed by :func:`shape_key`.

    Attributes
    ----------
    parts : tuple of str
        The vector parts embedded (sorted).
    scales : dict
        Their scales (median dissimilarity over the sample).
    index : usearch.index.Index
        The graph (``len(index)`` shapes).
    sample : dict
        What the database's sample gave (saved with the graph, so queries do not recompute it):
        ``scales`` of every part, the screening ``decision`` (FusionDecision.to_dict()) and the
        fusion ``settings`` it was made with.
    digests : dict
        key -> :func:`row_digests` of the vectors the graph holds for that shape: the state of the index it
        was built from (a row re-indexed, edited or removed since no longer matches).
    """

    parts: tuple[str, ...]
    scales: dict[str, float]
    index: object
    sample: dict = field(default_factory=dict)
    digests: dict[int, int] = field(default_factory=dict)

    @classmethod
    def build(cls, keys: np.ndarray, vectors: dict[str, np.ndarray], scales: dict[str, float]) -> "Shortlist":
        from usearch.index import Index

        X = embedding(vectors, scales)
        index = Index(ndim=X.shape[1], metric="l2sq", dtype="f32")
        keys = np.asarray(keys, dtype=np.uint64)
        if len(X):
            index.add(keys, X)
        return cls(tuple(sorted(vectors)), {p: float(scales[p]) for p in sorted(vectors)}, index,
                   digests=dict(zip(keys.tolist(), row_digests(vectors).tolist())))

    def __len__(self) -> int:
        return len(self.index)

    def add(self, keys: np.ndarray, vectors: dict[str, np.ndarray]) -> None:
        """Add (or replace) shapes."""
        keys = np.asarray(keys, dtype=np.uint64)
        self.remove(keys)
        if len(keys):
            self.index.add(keys, embedding(vectors, self.scales))
            self.digests.update(zip(keys.tolist(), row_digests(vectors).tolist()))

    def remove(self, keys) -> None:
        """Drop shapes (those not in the graph are ignored)."""
        present = [int(k) for k in np.asarray(keys, dtype=np.uint64).tolist() if k in self.index]
        if present:
            self.index.remove(present)
        for k in present:
            self.digests.pop(k, None)

    def changed(self, keys: np.ndarray, vectors: dict[str, np.ndarray]) -> tuple[np.ndarray, list[int]]:
        """(row positions whose vectors differ from the graph's or are not in it, keys in the graph that are not
        in ``keys``): what the index changed since the graph was saved."""
        now = row_digests(vectors).tolist()
        keys = np.asarray(keys, dtype=np.uint64).tolist()
        stale = np.array([i for i, (k, d) in enumerate(zip(keys, now)) if self.digests.get(k) != d], dtype=np.int64)
        return stale, sorted(set(self.digests) - set(keys))

    def search(self, vectors: dict[str, np.ndarray], count: int) -> np.ndarray:
        """Keys of the ``count`` nearest shapes to one query (``vectors``: part -> (d,) descriptor)."""
        q = embedding({p: np.asarray(v)[None] for p, v in vectors.items()}, self.scales)[0]
        matches = self.index.search(q, min(count, len(self.index)))
        return np.asarray(matches.keys, dtype=np.uint64)

    def save(self, path: Path) -> None:
        """Write the graph to ``path`` and its parts, scales, sample record, the digest of the graph file and
        the shapes' digests to ``path.json``, each atomically (a temporary file renamed into place): a process
        killed between the two leaves a record whose graph digest does not match, which :meth:`load` refuses."""
        import base64
        import os

        from topomatch.pipeline.contract import atomic_write_text

        path = Path(path)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        try:
            self.index.save(str(tmp))
            graph = hashlib.sha256(tmp.read_bytes()).hexdigest()
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
        table = np.array(sorted(self.digests.items()), dtype=np.uint64).reshape(-1, 2)
        record = {"schema": 2, "parts": list(self.parts), "scales": self.scales, "sample": self.sample,
                  "ndim": int(self.index.ndim), "graph_sha256": graph,
                  "digests": base64.b64encode(table.astype("<u8").tobytes()).decode("ascii")}
        record["record_sha256"] = _record_digest(record)
        atomic_write_text(Path(f"{path}.json"), json.dumps(record))

    @classmethod
    def load(cls, path: Path) -> tuple["Shortlist | None", str | None]:
        """(the shortlist saved at ``path``, None) when its two files are there and agree; (None, None) when
        there is none; (None, why) when they are there but cannot be used (damaged, foreign, from an older
        version, or not the pair written together): the caller rebuilds it and says why."""
        import base64

        from usearch.index import Index

        path, meta = Path(path), Path(f"{path}.json")
        if not path.exists() and not meta.exists():
            return None, None
        if not (path.is_file() and meta.is_file()):
            return None, "the graph or its record (.json) is missing or not a regular file"
        try:
            info = json.loads(meta.read_text())
            if info.get("schema") != 2:
                return None, f"record schema {info.get('schema')!r}, not 2 (an older or foreign file)"
            if info.get("record_sha256") != _record_digest(info):
                return None, "the record (.json) was edited after it was written"
            if hashlib.sha256(path.read_bytes()).hexdigest() != info["graph_sha256"]:
                return None, "the graph is not the one its record was written with (an interrupted save or a copy)"
            parts = tuple(str(p) for p in info["parts"])
            scales = {p: float(info["scales"][p]) for p in parts}
            table = np.frombuffer(base64.b64decode(info["digests"]), dtype="<u8").reshape(-1, 2)
            index = Index.restore(str(path))
        except (OSError, ValueError, RuntimeError, KeyError, TypeError, AttributeError, RecursionError) as exc:
            return None, f"unreadable ({type(exc).__name__}: {exc})"
        if index is None or int(index.ndim) != int(info.get("ndim", -1)) or len(index) != len(table):
            return None, "the graph's size or dimension does not match its record"
        digests = dict(zip(table[:, 0].tolist(), table[:, 1].tolist()))
        return cls(parts, scales, index, info.get("sample", {}), digests), None


def sample_fusion(descriptors: dict, fusion, options) -> tuple[dict[str, float], object]:
    """A large database's part scales and screening decision, from :func:`sample_rows` of it.

    ``descriptors``: part -> list of n :class:`Descriptor`; ``options``: part -> its MatchOptions.
    Returns ({part: median dissimilarity}, :class:`~topomatch.stages.retrieval.fusion.FusionDecision`).
    """
    from dataclasses import replace

    from topomatch.stages.retrieval.fusion import decide, median_scale
    from topomatch.stages.retrieval.ranking import dissimilarity_matrix

    sample = sample_rows(len(next(iter(descriptors.values()))))
    mats = [dissimilarity_matrix([descriptors[p][i] for i in sample], p, options(p)) for p in fusion.parts]
    return ({p: median_scale(M) for p, M in zip(fusion.parts, mats)},
            decide(mats, replace(fusion, rerank_k=None)))


def vector_parts(decision) -> tuple[str, ...]:
    """The kept parts a shortlist embeds: the vector ones (sorted)."""
    from topomatch.stages.retrieval.catalogue import get_method

    return tuple(sorted(p for p in decision.kept if get_method(p).kind == "vector"))


def shortlisted_dissimilarities(query: dict, descriptors: dict, fusion, ann: Shortlist, keys: np.ndarray,
                                scales: dict[str, float], decision, options, count: int) -> np.ndarray:
    """(n,) fused dissimilarities of one query: exact on its ``count`` shortlisted shapes, inf elsewhere.

    ``query``: part -> the query's Descriptor; ``keys``: (n,) the database shapes' graph keys.
    """
    from topomatch.stages.retrieval.fusion import fuse, scale_factor
    from topomatch.stages.retrieval.ranking import dissimilarities

    found = ann.search({p: query[p].data.ravel() for p in ann.parts}, count)
    order = np.argsort(keys, kind="stable")
    at = np.minimum(np.searchsorted(keys[order], found), len(keys) - 1)
    cand = order[at][keys[order][at] == found]  # the database rows of the keys found (a stale key is skipped)
    rows = [dissimilarities(query[p], [descriptors[p][i] for i in cand], p, options(p)) for p in decision.kept]
    d = np.full(len(keys), np.inf)
    d[cand] = fuse(rows, [scales[p] * scale_factor(fusion, decision, p) for p in decision.kept], fusion.order_weights)
    return d
