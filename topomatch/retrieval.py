"""Shape matching and retrieval: the Python API behind ``topomatch match | index | query | evaluate``.

Every method is a record of :mod:`topomatch.stages.retrieval.catalogue`; its descriptor is made by
its stage chain through the engine's runner (and, for an index, its executors and stage cache).

- :func:`match`: the dissimilarity of two meshes (and the endpoint correspondence for an endpoint method);
- :func:`index`: descriptors of a collection into a SQLite shape index (:mod:`topomatch.shape_index`):
  unchanged meshes are skipped, an interrupted index resumes, a bad mesh is recorded as failed;
- :func:`open_index`: a :class:`Collection` to :meth:`~Collection.query` (ranked closest shapes) and
  :meth:`~Collection.evaluate` (PSB metrics of the labelled shapes).

A fused method (``topomatch``) indexes each of its parts and ranks by their fused, re-ranked
dissimilarities; it needs a collection, so :func:`match` takes a single method.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from topomatch.pipeline.config import Experiment, build_experiment
from topomatch.pipeline.errors import ConfigError, InputError, InputWarning, StageError
from topomatch.pipeline.files import check_writable_folder
from topomatch.pipeline.item import ItemResult, run_item
from topomatch.shape_index import COMMIT_SECONDS, Row, ShapeIndex
from topomatch.stages.retrieval.catalogue import DEFAULT_METHOD, DEFAULT_PAIR_METHOD, Method, get_method
from topomatch.stages.retrieval.descriptor import Descriptor, MatchOptions

#: Suffixes of the mesh files an index takes from a folder (optionally .gz).
MESH_SUFFIXES = (".off", ".obj", ".ply", ".stl")

#: The matching options (MatchOptions fields) that match, query and evaluate take.
MATCH_OPTIONS = ("match.correspondence", "match.dissimilarity", "match.unmatched_cost", "match.endpoint_window")


# --------------------------------------------------------------------------- descriptors


def method_experiment(method: str, paths: list[Path], *, workers: int | None = 1,
                      executor: str | Mapping[str, Any] | None = None) -> Experiment:
    """The experiment that computes ``method``'s descriptor for each mesh path (``workers`` None: all
    cores; ``executor``: see :func:`executor_settings`)."""
    m = get_method(method)
    if m.kind == "fusion":
        raise ConfigError(f"{method} is a fusion: its parts {', '.join(m.parts)} have the descriptors")
    return build_experiment({
        "name": f"index-{method}",
        "inputs": {"meshes": [str(p) for p in paths] or ["(no input)"]},
        "stages": list(m.chain),
        "executor": executor_settings(workers, executor),
    }, resolve_inputs=bool(paths))


def executor_settings(workers: int | None, executor: str | Mapping[str, Any] | None) -> dict[str, Any]:
    """The config's ``executor:`` mapping for ``workers`` and ``executor``: a kind (``"local"``, ``"dask"``), a
    mapping of executor settings (``{"kind": "dask", "address": "tcp://host:8786"}``), or None (local processes).

    Raises
    ------
    ConfigError
        A setting that is malformed or does not apply to the executor (``address`` with ``kind: local``,
        ``workers`` with a scheduler address: :meth:`~topomatch.pipeline.config.ExecutorConfig.check`).
    """
    from topomatch.pipeline.config import ExecutorConfig
    from topomatch.pipeline.params import validate_json_strict

    settings = {"workers": workers, **({"kind": executor} if isinstance(executor, str) else dict(executor or {}))}
    validate_json_strict(ExecutorConfig, settings, "executor").check()
    return settings


def params_of(experiment: Experiment) -> tuple[dict, str]:
    """A method's resolved stage chain and its hash (part of the index key)."""
    resolved = experiment.resolved()
    params = {"stages": resolved["stages"], "stage_versions": resolved["stage_versions"]}
    return params, hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]


def compute_descriptor(path: str | Path, method: str, cache: str | None = None) -> tuple[Descriptor, ItemResult]:
    """Descriptor of one mesh file (through the stage cache ``cache``, if any).

    Raises
    ------
    InputError
        The file does not exist.
    StageError
        A stage failed (the message names the mesh and the reason).
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    (item,) = method_experiment(method, [path.resolve()]).items()
    result = run_item(item, cache)
    if not result.ok:
        raise StageError(result.error or f"{path}: failed")
    return result.final("descriptor"), result


def _save_quietly(ann, path: Path) -> None:
    """Save a shortlist graph beside its index; a read-only folder still answers, from the graph in memory."""
    try:
        ann.save(path)
    except OSError:
        pass


def _descriptor_shape(a: np.ndarray) -> tuple:
    """What every descriptor of one method shares: a vector's length, an endpoint table's columns per endpoint."""
    return a.shape if a.ndim == 1 else a.shape[1:]


def usable_rows(rows: list[Row], method: str, db: str | Path) -> list[Row]:
    """``rows``, after checking that each stored descriptor is what ``method`` makes: read, finite, of its kind
    and shape (a vector of the rows' common length; an (n, c) endpoint table with the rows' common column count
    and n = ``n_endpoints``). Any other (a damaged, NULL, scalar, NaN, shorter or longer descriptor: an index
    edited by hand or by another program) is an InputError that names the first such row and counts them."""
    from collections import Counter

    read = [r for r in rows if r.descriptor is not None and r.descriptor.ndim in (1, 2)]
    common = Counter(_descriptor_shape(r.descriptor) for r in read).most_common(1)
    expected = common[0][0] if common else None
    good, bad = [], []
    seen: dict[str, int] = {}
    for r in rows:
        d = r.descriptor
        want = {"vector": 1, "endpoints": 2}.get(r.kind or "")
        if r.path in seen:
            bad.append((r, f"the same mesh as row {seen[r.path]} (an answer would count it twice)"))
        elif d is None:
            bad.append((r, r.problem or "no descriptor stored (NULL) on a row marked ok"))
        elif d.dtype.kind != "f" or d.dtype.itemsize < 4:
            bad.append((r, f"dtype {d.dtype}, not the floating-point array topomatch writes"))
        elif want is not None and d.ndim != want:
            bad.append((r, f"a {d.ndim}-D array in a row of kind {r.kind!r} (a {want}-D array is stored there)"))
        elif d.ndim not in (1, 2) or (d.ndim == 1 and d.size == 0):  # an endpoint table may have no rows
            bad.append((r, f"a descriptor of shape {d.shape}, not a vector or an endpoint table"))
        elif not np.all(np.isfinite(d)):
            bad.append((r, f"{int((~np.isfinite(d)).sum())} NaN or infinite values"))
        elif _descriptor_shape(d) != expected:
            what = "length" if d.ndim == 1 else "columns per endpoint"
            bad.append((r, f"shape {d.shape} where most rows of {method} have {what} {expected[0]}"))
        elif d.ndim == 2 and r.n_endpoints is not None and d.shape[0] != r.n_endpoints:
            bad.append((r, f"{d.shape[0]} endpoint rows where the row says {r.n_endpoints} endpoints"))
        else:
            good.append(r)
        seen.setdefault(r.path, r.id)
    if bad:
        first, why = bad[0]
        raise InputError(db, f"row {first.id} ({first.path}) of {method}: {why}; {len(bad)} of the {len(rows)} "
                             f"{method} rows hold a descriptor that topomatch did not write (an answer without them "
                             f"would be silently partial): delete those rows (or the index) and run topomatch index "
                             f"again")
    return good


def _options(method: Method, options: dict[str, Any] | None) -> MatchOptions:
    """The method's matching options with ``options`` over them (ConfigError naming every bad one, as the CLI's)."""
    from pydantic import ValidationError

    from topomatch.pipeline.params import format_validation_error

    try:
        return method.match_options(**(options or {}))
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, "options")) from None


# --------------------------------------------------------------------------- match


@dataclass(frozen=True)
class MatchResult:
    """The dissimilarity of two meshes, with the fields ``topomatch match --json`` prints.

    ``correspondence`` (endpoint methods only): one entry per matched endpoint pair, ``a`` and ``b``
    (endpoint indices), ``cost`` (Phi) and both endpoints' features; ``n_endpoints_a``/``n_endpoints_b``
    the endpoint counts (None for vector methods; named like ``Skeleton.n_endpoints``, docs/cli_json.md).
    """

    a: str
    b: str
    method: str
    dissimilarity: float
    n_endpoints_a: int | None = None
    n_endpoints_b: int | None = None
    correspondence: list[dict[str, Any]] | None = None

    @property
    def endpoints_a(self) -> int | None:
        """Deprecated Python alias of :attr:`n_endpoints_a` (the JSON has only the new name)."""
        return self.n_endpoints_a

    @property
    def endpoints_b(self) -> int | None:
        """Deprecated Python alias of :attr:`n_endpoints_b`."""
        return self.n_endpoints_b

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k, v in dataclasses.asdict(self).items() if v is not None}


def match(a: str | Path, b: str | Path, *, method: str = DEFAULT_PAIR_METHOD,
          options: dict[str, Any] | None = None) -> MatchResult:
    """Dissimilarity of two mesh files by ``method`` (default: the catalogue's pair default).

    ``options``: endpoint matching options (``correspondence``, ``dissimilarity``,
    ``unmatched_cost``, ``endpoint_window``; each defaults to the method's own).
    """
    from topomatch.stages.matching.dissimilarity import match_features
    from topomatch.stages.retrieval.ranking import dissimilarities

    m = get_method(method)
    if m.kind == "fusion":
        raise ConfigError(f"match: {method} is a fused method whose scales and re-ranking come from a collection; "
                          f"index the meshes and query them, or match with one of its parts ({', '.join(m.parts)})")
    o = _options(m, options) if m.kind == "endpoints" else None  # a bad option before any descriptor is computed
    da, _ = compute_descriptor(a, method)
    db, _ = compute_descriptor(b, method)
    if o is None:
        return MatchResult(str(a), str(b), method, float(dissimilarities(da, [db], m)[0]))
    r = match_features(da.data, db.data, correspondence=o.correspondence, dissimilarity=o.dissimilarity,
                       unmatched_cost=o.unmatched_cost)
    pairs = [{"a": int(i), "b": int(j), "cost": float(c), "features_a": da.data[i].tolist(),
              "features_b": db.data[j].tolist()} for i, j, c in zip(r.rows, r.cols, r.costs)]
    return MatchResult(str(a), str(b), method, float(r.dissimilarity), int(len(da.data)), int(len(db.data)), pairs)


# --------------------------------------------------------------------------- index


def mesh_files(paths: list[str | Path]) -> list[Path]:
    """Mesh files from files and folders (recursive), sorted, de-duplicated, resolved."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += [f for f in sorted(p.rglob("*")) if f.is_file() and _is_mesh(f)]
        elif p.exists():
            out.append(p)
        else:
            raise InputError(p, "file not found")
    return list(dict.fromkeys(f.resolve() for f in out))


def _is_mesh(path: Path) -> bool:
    return path.name.lower().removesuffix(".gz").endswith(MESH_SUFFIXES)


def cache_dir(db: str | Path) -> str:
    """The stage cache of an index: ``<db>.cache`` next to it."""
    db = Path(db)
    return str(db.with_name(db.name + ".cache"))


@dataclass
class PartReport:
    """What indexing did for one part method."""

    method: str
    params_hash: str
    todo: int
    done: int = 0
    failed: int = 0
    failed_before: int = 0  # meshes recorded as failed by an earlier run, skipped (retry_failed retries them)
    seconds: float = 0.0
    failures: list[str] = field(default_factory=list)


@dataclass
class IndexReport:
    """What :func:`index` did: per part method, the meshes indexed, failed and skipped."""

    db: str
    method: str
    n_files: int
    parts: list[PartReport]
    seconds: float
    open_meshes: list[str] = field(default_factory=list)  # meshes indexed now that have boundaries
    multi_component_meshes: list[str] = field(default_factory=list)  # ... with several components (largest kept)
    removed: int = 0  # rows of files no longer in the indexed folders, deleted
    unmatched_labels: list[str] = field(default_factory=list)  # labels-file paths that are no mesh file given

    @property
    def failed(self) -> int:
        """Meshes (per part) without a descriptor: failed now or in an earlier run."""
        return sum(p.failed + p.failed_before for p in self.parts)


def index(paths: list[str | Path], db: str | Path, *, method: str = DEFAULT_METHOD, labels: str | Path | None = None,
          workers: int | None = None, executor: str | Mapping[str, Any] | None = None, retry_failed: bool = False,
          progress: bool = False) -> IndexReport:
    """Index every mesh file of ``paths`` (files or folders) into the shape index ``db``.

    ``workers``: processes of the local pool or of a new local dask cluster (None: all cores); ``executor``:
    ``"local"`` (default), ``"dask"``, or the executor settings as a mapping, e.g. ``{"kind": "dask",
    "address": "tcp://host:8786"}`` (a cluster: docs/cluster.md).

    One work unit per mesh runs every part method of ``method`` on it, so the stages the parts
    share (load, clean, decimate, spectrum) are computed once, in memory, and the workers share out
    the meshes. Unchanged meshes (same content, method and parameters) are skipped.

    Open meshes (with boundaries): the intrinsic parts of the default method cap every hole of their
    decimated copy (``fill_holes``: a fan to each boundary loop's centroid) before the spectrum, heat
    kernel and skeleton; methods without that stage (``shapedna-full``, the thesis skeletons) use natural
    (Neumann) boundary conditions. A mesh with several components keeps its largest. :class:`IndexReport`
    lists both.

    Raises
    ------
    ConfigError
        Executor settings that are malformed or do not apply (before anything is read or written).
    InputError
        No mesh file found, a path that does not exist, an unreadable labels file.
    ExecutorError
        The dask scheduler was lost or has no workers; the meshes indexed before are kept.
    """
    from tqdm import tqdm

    from topomatch.pipeline import executors
    from topomatch.pipeline.cache import hash_file
    from topomatch.stages.retrieval.labels import read_labels

    executor = executor_settings(workers, executor)  # refused before anything is read or written
    files = mesh_files(paths)
    if not files:
        raise InputError(None, f"no mesh files ({', '.join(MESH_SUFFIXES)}, optionally .gz) in "
                               f"{' '.join(map(str, paths))}")
    label_of = read_labels(labels) if labels else {}
    db_path = Path(db)
    hashes = {str(f): hash_file(f) for f in files}
    shapes: dict[str, dict] = {}  # mesh -> the summary of the clean of its full mesh (topology after)
    t0 = time.perf_counter()
    plans: dict[str, tuple[PartReport, dict]] = {}
    todo: dict[str, list] = {}  # mesh -> its part items: one work unit, the shared stages computed once
    with ShapeIndex(db_path) as store:
        folders = [Path(p).resolve() for p in paths if Path(p).is_dir()]
        present = {str(f) for f in files}
        removed = store.remove_missing(folders, present, get_method(method).parts) if folders else 0
        for part in get_method(method).parts:
            experiment = method_experiment(part, files, workers=workers, executor=executor)
            params, phash = params_of(experiment)
            known = store.known(part, phash, include_failed=not retry_failed)
            mine = [dataclasses.replace(item, item_id=f"{part}/{item.item_id}") for item in experiment.items()
                    if hashes[item.input_path] not in known]
            before = 0 if retry_failed else len(store.failed(part, phash) & set(hashes.values()))
            plans[part] = (PartReport(part, phash, len(mine), failed_before=before), params)
            for item in mine:
                todo.setdefault(item.input_path, []).append(item)
        n_items = sum(map(len, todo.values()))
        committed = time.monotonic()
        with tqdm(total=n_items, desc=f"index {method}", unit="item", disable=not progress) as bar:
            try:
                # the workers send back a small record per item with its descriptor; the rest stays in the stage
                # cache. This process alone writes the index: committing at most once a second (COMMIT_SECONDS)
                # and whenever it stops (an error, Ctrl-C, a lost scheduler), so what finished is kept.
                for group in executors.execute_groups(list(todo.values()), cache_dir(db_path), experiment.raw.executor,
                                                      keep=("descriptor",)):
                    for r in group:
                        part = r.item_id.split("/", 1)[0]
                        report, params = plans[part]
                        d = r.final("descriptor")
                        store.put(content_hash=hashes[r.input_path], path=r.input_path,
                                  label=label_of.get(r.input_path), method=part, params_hash=report.params_hash,
                                  params=params, status="ok" if r.ok else "failed", reason=r.error,
                                  n_endpoints=None if d is None else d.n_endpoints, kind=None if d is None else d.kind,
                                  descriptor=None if d is None else d.data, seconds=sum(r.seconds.values()),
                                  commit=False)
                        shapes.setdefault(r.input_path, _first_clean(r))
                        report.done += r.ok
                        report.failed += not r.ok
                        report.seconds += sum(r.seconds.values())
                        bar.update()
                    if time.monotonic() - committed >= COMMIT_SECONDS:
                        store.commit()
                        committed = time.monotonic()
            except BaseException:
                with contextlib.suppress(InputError):  # the rows written so far are kept; the first error is told
                    store.commit()
                raise
            store.commit()
        if label_of:
            store.set_labels(label_of)
        for report, _ in plans.values():
            if report.failed or report.failed_before:
                report.failures = [row.reason or "" for row in store.rows(report.method, report.params_hash,
                                                                          status="failed")]
    if get_method(method).fusion is not None:
        _prepare_ranking(db_path, method, set(todo))
    cleans = {path: c for path, c in shapes.items() if c is not None}
    return IndexReport(str(db_path), method, len(files), [p for p, _ in plans.values()], time.perf_counter() - t0,
                       sorted(p for p, c in cleans.items() if c["boundary_loops"] > 0),
                       sorted(p for p, c in cleans.items() if c["dropped_components"] > 0), removed,
                       sorted(set(label_of) - present))


#: Fused indexes of up to this many shapes save their part matrices when indexed, so that the first query
#: does not compute them (~1 s for 400 shapes, ~6 s for 1,000: the AGD part is n^2 endpoint matchings).
PREPARED_MATRICES_MAX = 1000


def _prepare_ranking(db: Path, method: str, indexed: set[str]) -> None:
    """What a fused query needs, made when indexing: a large index's shortlist graph (``<db>.ann``) kept in
    step with its rows, or a small one's part matrices saved in its cache; ``indexed``: the meshes
    (re)computed by this run."""
    from topomatch.stages.retrieval.shortlist import LARGE_INDEX

    collection = Collection(db)
    counts = {name: n for name, _, n in collection.methods()}
    n = min(counts.get(p, 0) for p in get_method(method).parts)
    if n >= LARGE_INDEX:
        collection.shortlist(method, refresh=indexed)
    elif 2 <= n <= PREPARED_MATRICES_MAX:
        collection.part_matrices(method, collection.parts(method)[1])


def _first_clean(result: ItemResult) -> dict | None:
    """The summary of the first clean of an item's chain (the full mesh's: its topology after cleaning and the
    components dropped), or None; read from the record, so the cleaned mesh stays in the worker's cache."""
    return next((s for s in map(result.summary, result.results) if "dropped_components" in s), None)


# --------------------------------------------------------------------------- query / evaluate


@dataclass(frozen=True)
class QueryResult:
    """The ranked closest shapes to a query, with the fields ``topomatch query --json`` prints.

    ``results``: one entry per shape, ``rank``, ``path``, ``label``, ``dissimilarity``, ``n_endpoints``
    (its endpoint count, or None); ``n_endpoints``: the query's endpoint count (or None); ``seconds``:
    ``descriptor`` and ``ranking``; ``indexed``: the shapes ranked; ``fusion`` (fused methods): the
    parts kept and dropped by the screening, their agreement and the re-ranking neighbours.
    """

    query: str
    method: str
    n_endpoints: int | None
    indexed: int
    seconds: dict[str, float]
    results: list[dict[str, Any]]
    fusion: dict[str, Any] | None = None

    @property
    def endpoints(self) -> int | None:
        """Deprecated Python alias of :attr:`n_endpoints` (the JSON has only the new name)."""
        return self.n_endpoints

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Evaluation:
    """PSB metrics of a method on the labelled shapes of an index, and where the matrix was written."""

    method: str
    n: int
    matrix: str
    matrix_seconds: float
    metrics: Any = field(repr=False)  # RetrievalMetrics
    fusion: dict[str, Any] | None = None  # fusions: FusionDecision.to_dict()

    def to_dict(self) -> dict[str, Any]:
        return {"method": self.method, "n": self.n, "matrix": self.matrix, "matrix_seconds": self.matrix_seconds,
                **self.metrics.as_dict(), **({"fusion": self.fusion} if self.fusion is not None else {})}


class Collection:
    """An open shape index: :meth:`query` and :meth:`evaluate` with any indexed method."""

    def __init__(self, db: str | Path):
        self.db = Path(db)
        if self.db.exists() and not self.db.is_file():
            raise InputError(self.db, "not a regular file (a folder, device or pipe), so not an index")
        if not self.db.exists():
            raise InputError(self.db, "index not found (create it with topomatch index)")

    def __repr__(self) -> str:
        return f"Collection({str(self.db)!r})"

    def methods(self) -> list[tuple[str, str, int]]:
        """(method, params hash, shapes indexed ok) present in the index."""
        with ShapeIndex(self.db, readonly=True) as store:
            return store.methods()

    def _rows(self, method: str, asked: str | None = None) -> list[Row]:
        """The ok rows of ``method`` (a part of ``asked``, default itself) with the current parameters; else a
        :class:`ConfigError` saying what the index holds and what to do."""
        asked = asked or method
        phash = params_of(method_experiment(method, []))[1]
        with ShapeIndex(self.db, readonly=True) as store:
            rows = usable_rows(store.rows(method, phash), method, self.db)
            if not rows:
                present = store.methods()
                listing = ", ".join(f"{m} ({n} ok)" for m, _, n in present) or "nothing"
                whose = f"method {asked!r}" + (f" (its part {method!r})" if method != asked else "")
                if any(m == method and h == phash for m, h, _ in present):
                    hint = (f"; every mesh failed for {method} when indexed (the failures were listed then; "
                            f"topomatch index --retry-failed recomputes them)")
                elif any(m == method for m, _, _ in present):
                    hint = (f"; its {method} rows were made with other parameters or stage versions: run topomatch "
                            f"index again to update them")
                else:
                    usable = list(dict.fromkeys(m for m, _, n in present if n))
                    hint = (f"; pass --method {' or '.join(usable)} to use what it holds, or index it with "
                            f"--method {asked}" if usable else f"; index it with --method {asked}")
                raise ConfigError(f"{self.db}: no shapes indexed for {whose} with the current parameters "
                                  f"(the index has: {listing}){hint}")
        return rows

    def parts(self, method: str) -> tuple[list[Row], dict[str, list[Descriptor]]]:
        """Index rows present for every part of ``method`` (same order), and {part: descriptors}."""
        parts = get_method(method).parts
        indexed = {part: self._rows(part, method) for part in parts}
        common = set.intersection(*({r.path for r in rows} for rows in indexed.values()))
        partial = set.union(*({r.path for r in rows} for rows in indexed.values())) - common
        if partial:
            warnings.warn(f"{self.db}: {len(partial)} mesh(es) lack a row of some part of {method} and are left out "
                          f"(e.g. {sorted(partial)[0]}); run topomatch index on them with --method {method}",
                          InputWarning, stacklevel=3)
        rows = [r for r in indexed[parts[0]] if r.path in common]
        descriptors = {}
        for part, part_rows in indexed.items():
            by_path = {r.path: Descriptor(r.kind, r.descriptor, r.n_endpoints) for r in part_rows}
            descriptors[part] = [by_path[r.path] for r in rows]
        return rows, descriptors

    def _part_options(self, part: str, method: Method, options: dict[str, Any] | None) -> MatchOptions:
        """A part's matching options: the given ones for a single method, each part's own in a fusion."""
        return get_method(part).match_options() if method.kind == "fusion" else _options(method, options)

    def part_matrices(self, method: str, descriptors: dict[str, list[Descriptor]],
                      options: dict[str, Any] | None = None, slot: str = "all") -> list[np.ndarray]:
        """The (n, n) dissimilarity matrix of each part of ``method`` (itself for a single method), saved in the
        index's cache (``<db>.cache``, one per ``slot``: ``"all"`` shapes for queries, ``"labelled"`` ones for
        evaluation) and read back while the part's descriptors and options are the same."""
        from topomatch.pipeline.cache import Cache
        from topomatch.stages.retrieval.ranking import saved_dissimilarity_matrix

        m = get_method(method)
        cache = Cache(cache_dir(self.db))
        return [saved_dissimilarity_matrix(descriptors[p], p, self._part_options(p, m, options), cache, slot)
                for p in m.parts]

    def matrix(self, method: str, descriptors: dict[str, list[Descriptor]],
               options: dict[str, Any] | None = None) -> np.ndarray:
        """Full dissimilarity matrix of ``method`` (fused and re-ranked for a fusion)."""
        return _fused(get_method(method), self.part_matrices(method, descriptors, options))[0]

    def query(self, mesh: str | Path, *, k: int = 10, method: str = DEFAULT_METHOD,
              options: dict[str, Any] | None = None, shortlist: bool | None = None) -> QueryResult:
        """The ``k`` closest indexed shapes to a mesh file (its descriptors go through the index's cache).

        ``shortlist`` (fusions): rank through the approximate-nearest-neighbour shortlist
        (:mod:`topomatch.stages.retrieval.shortlist`); None = when the index holds at least
        ``LARGE_INDEX`` shapes.
        """
        from topomatch.stages.retrieval.fusion import decide, fused_query
        from topomatch.stages.retrieval.ranking import dissimilarities
        from topomatch.stages.retrieval.shortlist import LARGE_INDEX

        if not (isinstance(k, int) and k >= 1):
            raise ConfigError(f"k must be a whole number of at least 1, got {k!r}")
        m = get_method(method)
        rows, descriptors = self.parts(method)
        t = time.perf_counter()
        query = {p: compute_descriptor(mesh, p, cache_dir(self.db))[0] for p in m.parts}
        for p in m.parts:  # every stored row can agree with the others and still not be what this version computes
            stored, made = descriptors[p][0].data, query[p].data
            if stored.ndim != made.ndim or _descriptor_shape(stored) != _descriptor_shape(made):
                raise InputError(self.db, f"its {p} descriptors have shape {stored.shape}, and this version computes "
                                          f"{made.shape} for the query: the index was made by another version or "
                                          f"edited; delete it and run topomatch index again")
        t_desc = time.perf_counter() - t
        t = time.perf_counter()
        large = m.fusion is not None and (shortlist if shortlist is not None else len(rows) >= LARGE_INDEX)
        decision = None
        if large:
            d, decision = self._shortlisted(m, rows, descriptors, query, k, options)
        elif m.fusion is not None:
            rows_d = [dissimilarities(query[p], descriptors[p], p, self._part_options(p, m, options)) for p in m.parts]
            mats = self.part_matrices(method, descriptors, options)
            chosen = decide(mats, m.fusion, graph_size=len(rows) + 1)  # the query joins the graph
            d, decision = fused_query(rows_d, mats, m.fusion, chosen), chosen.to_dict()
        else:
            d = dissimilarities(query[m.name], descriptors[m.name], m.name, self._part_options(m.name, m, options))
        if np.isnan(d).any():  # never dropped silently (inf, a shape outside the shortlist, is)
            raise StageError(f"{self.db}: the {method} ranking of {mesh} is undefined (NaN) for "
                             f"{int(np.isnan(d).sum())} of {len(d)} shapes")
        order = np.argsort(d, kind="stable")[:k]
        t_rank = time.perf_counter() - t
        endpoints = next((q.n_endpoints for q in query.values() if q.n_endpoints is not None), None)
        results = [{"rank": i + 1, "path": rows[j].path, "label": rows[j].label, "dissimilarity": float(d[j]),
                    "n_endpoints": rows[j].n_endpoints} for i, j in enumerate(order) if np.isfinite(d[j])]
        return QueryResult(str(mesh), method, endpoints, len(rows), {"descriptor": t_desc, "ranking": t_rank},
                           results, decision)

    def shortlist(self, method: str = DEFAULT_METHOD, options: dict[str, Any] | None = None,
                  refresh: set[str] | frozenset[str] = frozenset()):
        """The approximate-nearest-neighbour shortlist of a fused method, loaded from ``<db>.ann``,
        brought up to date (new shapes added, the ``refresh`` paths re-embedded) or built, and saved."""
        m = get_method(method)
        rows, descriptors = self.parts(method)
        return self._shortlist(m, rows, descriptors, options, refresh)[0]

    def _shortlist(self, m: Method, rows: list[Row], descriptors: dict[str, list[Descriptor]],
                   options: dict[str, Any] | None, refresh: set[str] | frozenset[str] = frozenset()):
        """(shortlist, (n,) keys of ``rows``, part scales, screening decision): the saved shortlist as it is
        when it already holds exactly these shapes with the same fusion settings; else the sample's
        scales and screening recomputed and the graph brought up to date (or built), then saved."""
        from topomatch.stages.retrieval.fusion import FusionDecision
        from topomatch.stages.retrieval.shortlist import Shortlist, sample_fusion, shape_key, vector_parts

        keys = np.array([shape_key(r.path) for r in rows], dtype=np.uint64)
        path = self.db.with_name(self.db.name + ".ann")
        ann, problem = Shortlist.load(path)
        if ann is not None and not set(ann.parts) <= set(descriptors):
            ann, problem = None, f"it embeds parts ({', '.join(ann.parts)}) that {m.name} does not have"
        if ann is not None:
            dims = sum(descriptors[p][0].data.size for p in ann.parts) if rows else int(ann.index.ndim)
            if dims != int(ann.index.ndim):
                ann, problem = None, f"its vectors have {int(ann.index.ndim)} dimensions, the index's {dims}"
        if problem:
            warnings.warn(f"{path}: {problem}; ignored, and rebuilt from the index", InputWarning, stacklevel=3)
            ann = None

        def vectors(idx, parts):
            return {p: np.stack([descriptors[p][i].data.ravel() for i in idx]) for p in parts}

        settings = [m.fusion.screen, list(m.fusion.order_weights or ())]
        if m.fusion.agreement_rule != "mean":  # (shortlists saved before the rule existed stay valid for 'mean')
            settings.append(m.fusion.agreement_rule)
        with ShapeIndex(self.db, readonly=True) as store:
            generation = store.generation()
        if (ann is not None and not refresh and generation is not None and ann.sample.get("generation") == generation
                and ann.sample.get("settings") == settings and len(ann) == len(keys)
                and bool(np.all(ann.index.contains(keys)))):  # this index, no row changed since the graph was saved
            d = ann.sample["decision"]
            return ann, keys, ann.sample["scales"], dataclasses.replace(FusionDecision.from_dict(d), rerank_k=None)
        # the rows changed (or the index cannot say): compare the graph's vectors with the rows', shape by shape
        stale, gone = (ann.changed(keys, vectors(range(len(rows)), ann.parts)) if ann is not None and len(rows)
                       else (np.arange(len(rows)), []))
        stale = np.union1d(stale, [i for i, r in enumerate(rows) if r.path in refresh]).astype(np.int64)
        if ann is not None and not len(stale) and not gone and ann.sample.get("settings") == settings:
            ann.sample["generation"] = generation  # the graph holds exactly the index's current vectors
            _save_quietly(ann, path)
            d = ann.sample["decision"]
            return ann, keys, ann.sample["scales"], dataclasses.replace(FusionDecision.from_dict(d), rerank_k=None)
        scales, decision = sample_fusion(descriptors, m.fusion, lambda p: self._part_options(p, m, options))
        parts = vector_parts(decision)
        if not parts:
            raise ConfigError(f"{self.db}: the shortlist needs a vector part, and the screening kept only "
                              f"{', '.join(decision.kept)}")
        if ann is None or ann.parts != parts or any(abs(ann.scales[p] / scales[p] - 1) > 0.2 for p in parts):
            ann = Shortlist.build(keys, vectors(range(len(rows)), parts), {p: scales[p] for p in parts})
        else:  # re-embed what changed (re-indexed, edited, new), drop what left the index
            ann.remove(gone)
            if len(stale):
                ann.add(keys[stale], vectors(stale, parts))
        ann.sample = {"scales": scales, "decision": decision.to_dict(), "settings": settings, "generation": generation}
        _save_quietly(ann, path)
        return ann, keys, scales, decision

    def _shortlisted(self, m: Method, rows: list[Row], descriptors: dict[str, list[Descriptor]],
                     query: dict[str, Descriptor], k: int, options: dict[str, Any] | None):
        """(n,) dissimilarities of a query, exact on its shortlist and inf elsewhere, and the fusion decision."""
        from topomatch.stages.retrieval.shortlist import SHORTLIST, shortlisted_dissimilarities

        ann, keys, scales, decision = self._shortlist(m, rows, descriptors, options)
        count = max(SHORTLIST, 20 * k)
        d = shortlisted_dissimilarities(query, descriptors, m.fusion, ann, keys, scales, decision,
                                        lambda p: self._part_options(p, m, options), count)
        return d, {**decision.to_dict(), "rerank_k": None, "shortlist": min(count, len(rows))}

    def evaluate(self, *, method: str = DEFAULT_METHOD, options: dict[str, Any] | None = None,
                 out: str | Path | None = None) -> Evaluation:
        """PSB metrics (NN, FT, ST, E, DCG, mAP) of the labelled shapes; the matrix goes to ``out`` (.npz,
        default ``<db>.<method>.npz``)."""
        from topomatch.stages.retrieval.metrics import PSB_CUTOFF, retrieval_metrics

        rows, descriptors = self.parts(method)
        keep = [i for i, r in enumerate(rows) if r.label]
        if len(keep) < 2:
            raise ConfigError(f"{self.db}: fewer than two labelled shapes for {method}; index with --labels (a labels "
                              f"file labels the meshes whose paths, relative to the file's folder, it lists: index "
                              f"warns about rows that match no mesh)")
        rows = [rows[i] for i in keep]
        labels = np.array([r.label for r in rows])
        path = Path(out) if out else self.db.with_suffix(f".{method}.npz")
        if path.suffix != ".npz":  # numpy would add it: name the file that is written
            path = path.with_name(path.name + ".npz")
        check_writable_folder(path.parent, create=False)  # before the matrix is computed, not after
        sizes = {c: int((labels == c).sum()) for c in set(labels)}
        if max(sizes.values()) < PSB_CUTOFF + 1:
            raise InputError(self.db, f"no class has {PSB_CUTOFF + 1} or more labelled shapes (largest: "
                                      f"{max(sizes.values())}): nothing to evaluate (PSB evaluates a query only when "
                                      f"its class has at least {PSB_CUTOFF + 1} members)")
        t = time.perf_counter()
        m = get_method(method)
        parts = self.part_matrices(method, {p: [ds[i] for i in keep] for p, ds in descriptors.items()}, options,
                                   slot="labelled")
        D, decision = _fused(m, parts)
        seconds = time.perf_counter() - t
        metrics = retrieval_metrics(D, labels)
        np.savez_compressed(path, D=D, paths=np.array([r.path for r in rows]), labels=labels)
        return Evaluation(method, len(rows), str(path), seconds, metrics, decision)


def _fused(method: Method, part_matrices: list[np.ndarray]) -> tuple[np.ndarray, dict[str, Any] | None]:
    """A method's (n, n) matrix from its parts' (fused and re-ranked for a fusion), and for a fusion what
    it did (parts kept and dropped, their agreement, re-ranking k; None otherwise)."""
    from topomatch.stages.retrieval.fusion import decide, fused_matrix

    if method.fusion is None:
        return part_matrices[0], None
    decision = decide(part_matrices, method.fusion)
    return fused_matrix(part_matrices, method.fusion, decision), decision.to_dict()


def open_index(db: str | Path) -> Collection:
    """The shape index at ``db`` (created by :func:`index`)."""
    return Collection(db)
