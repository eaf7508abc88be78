"""Experiment configs: YAML -> a validated :class:`Experiment`.

A config names its inputs, the stage chain with parameters, optional sweeps,
the reports it writes and the executor::

    name: demo
    inputs: {meshes: ["{bundled}/meshes/torus.off"]}
    sweep: {noise.sigma: [0.0, 0.01]}        # grid over stage parameters
    stages:
      - load
      - clean: {components: largest}
      - noise: {sigma: 0.0, relative_to: bbox_diagonal, seed: 7}
      - measures
    reports:
      - mesh_gallery: {}
    executor: {kind: local}                  # or {kind: dask, address: ...}

YAML is read with the safe loader; unknown keys, wrong types and unknown stage
names are rejected with the config path of the problem
(``stages[2].noise.sigma: Input should be a valid number, got 'x'``).
"""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator
from topomatch.pipeline.contract import StageSpec
from topomatch.pipeline.mappings import deep_merge, set_path
from topomatch.pipeline.errors import ConfigError, InputError
from topomatch.pipeline.params import Params, validate_json_strict
from topomatch.pipeline.paths import display_path, resolve_input
from topomatch.pipeline.registry import get_report, get_stage
from topomatch.pipeline.yaml_loading import load_yaml

#: State entries that each kind of input provides before the first stage.
INPUT_STATE = {
    "meshes": ("path",),
    "images": ("path",),
    "pairs": ("fixed_path", "moving_path", "truth"),
    "pairs_csv": ("fixed_path", "moving_path", "truth"),
}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


#: The environment variable that names a dask scheduler (the one Dask's own ``Client()`` reads): used by
#: ``kind: dask`` when no ``address`` is given.
SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"

#: Seconds a dask run waits for its scheduler and for a worker when ``executor.timeout`` is not given.
DEFAULT_DASK_TIMEOUT = 60.0


class ExecutorConfig(_Strict):
    """Where the items of a run are computed."""

    kind: Literal["local", "dask"] = Field("local", description="local process pool or a dask cluster")
    workers: int | None = Field(None, ge=1, description="worker processes of the local pool or of a new local dask "
                                                        "cluster (default: all cores)")
    address: str | None = Field(None, min_length=1, description=f"dask scheduler to use, e.g. tcp://host:8786 "
                                f"(default: ${SCHEDULER_ENV}, else a new local dask cluster)")
    timeout: float | None = Field(None, gt=0, allow_inf_nan=False,
                                  description=f"dask: seconds to wait for the scheduler to answer and for a worker, "
                                              f"at the start or after every worker left (default: "
                                              f"{DEFAULT_DASK_TIMEOUT:g})")

    def scheduler(self) -> tuple[str | None, str]:
        """The dask scheduler this executor uses and where its address comes from (``executor.address``,
        or ``$DASK_SCHEDULER_ADDRESS`` when no address is given); ``(None, "")`` for a new local cluster or
        the local executor."""
        if self.kind != "dask":
            return None, ""
        if self.address:
            return self.address, "executor.address"
        env = os.environ.get(SCHEDULER_ENV, "").strip()
        return (env, f"${SCHEDULER_ENV}") if env else (None, "")

    def check(self) -> None:
        """Refuse the settings that do not apply to the chosen executor (they would be ignored).

        Raises
        ------
        ConfigError
            ``address`` or ``timeout`` with ``kind: local``; ``workers`` with a scheduler address (the
            cluster decides its workers), the address from the config or from ``$DASK_SCHEDULER_ADDRESS``.
        """
        if self.kind == "local":
            for name, flag in (("address", "--address"), ("timeout", "--dask-timeout")):
                if getattr(self, name) is not None:
                    raise ConfigError(f"executor.{name} ({flag}) applies only to the dask executor, and the executor "
                                      f"is local; set executor.kind: dask (--executor dask) or leave it out")
            return
        address, source = self.scheduler()
        if address is not None and self.workers is not None:
            leave = ("unset $" + SCHEDULER_ENV) if source.startswith("$") else "leave out executor.address (--address)"
            raise ConfigError(f"executor.workers ({self.workers}, --workers) does not apply with the dask scheduler at "
                              f"{address} (from {source}): that cluster decides its workers; leave out "
                              f"executor.workers (--set executor.workers=null), or {leave} to start a local cluster "
                              f"of {self.workers} workers")


class PairConfig(_Strict):
    """A fixed/moving image pair with an optional known transform."""

    fixed: str
    moving: str
    truth: dict[str, float] | None = Field(None, description="known parameters, e.g. {tx: 13, ty: 17, angle: 0}")
    label: str | None = Field(None, min_length=1, description="the pair's name in tables and figures, e.g. 'slice "
                                                             "30|slice 31' (default: the two file names)")


class PairsCsvConfig(_Strict):
    """Image pairs listed in a CSV file (paths relative to the CSV's folder)."""

    path: str
    fixed_column: str = "fixed"
    moving_column: str = "moving"
    truth_columns: dict[str, str] = Field(default_factory=dict, description="truth name -> CSV column")
    skip_missing_truth: bool = Field(True, description="leave out rows whose truth cells are empty")


class InputsConfig(_Strict):
    """Input files, as path templates ({bundled}, {data_root}, globs)."""

    meshes: list[str] = Field(default_factory=list)
    images: list[str] = Field(default_factory=list)
    pairs: list[PairConfig] = Field(default_factory=list)
    pairs_csv: PairsCsvConfig | None = None


@dataclass(frozen=True)
class InputUnit:
    """One input of a run: files for state entries (``paths``) and plain values (``values``)."""

    label: str
    paths: dict[str, Path]
    values: dict[str, Any] = field(default_factory=dict)

    @property
    def primary(self) -> Path:
        return next(iter(self.paths.values()))


#: Most sweep points a config may ask for (a grid's size is the product of its value counts).
MAX_SWEEP_POINTS = 10_000


class RawConfig(_Strict):
    """The structure of a config file, before stage names and params are resolved."""

    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
    description: str = ""
    inputs: InputsConfig = InputsConfig()
    sweep: dict[str, list[Any]] = Field(default_factory=dict)
    sweep_mode: Literal["grid", "one_at_a_time"] = Field(
        "grid", description="grid: every combination of the sweep values; one_at_a_time: the first value of "
                            "every key (the baseline), then each other value of one key with the rest at baseline")
    stages: list[str | dict[str, dict[str, Any] | None]] = Field(min_length=1)
    reports: list[str | dict[str, dict[str, Any] | None]] = Field(default_factory=list)
    executor: ExecutorConfig = ExecutorConfig()
    figure_format: list[Literal["png", "svg", "pdf"]] = Field(
        default_factory=lambda: ["png"], min_length=1,
        description="file formats of every figure (the run page shows the PNG, else the SVG; the others are linked)")
    dpi: int = Field(150, ge=50, le=1200, description="resolution of raster figures (PNG), dots per inch")

    @field_validator("figure_format", mode="before")
    @classmethod
    def _one_format(cls, value: Any) -> Any:
        return [value] if isinstance(value, str) else value

    @field_validator("sweep")
    @classmethod
    def _non_empty_sweeps(cls, value: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for key, values in value.items():
            if not values:
                raise ValueError(f"sweep {key!r} has no values")
        return value

    @model_validator(mode="after")
    def _bounded_sweep(self) -> "RawConfig":
        sizes = [len(v) for v in self.sweep.values()]
        points = math.prod(sizes) if self.sweep_mode == "grid" else 1 + sum(n - 1 for n in sizes)
        if points > MAX_SWEEP_POINTS:
            raise ValueError(f"the sweep has {points:,} points ({' x '.join(map(str, sizes))}), more than the "
                             f"{MAX_SWEEP_POINTS:,} a run may hold; split it into several configs")
        return self


@dataclass(frozen=True)
class StageCall:
    """One entry of the stage chain, with validated params."""

    index: int
    label: str  # unique within the chain: the name, or name#k for repeats
    spec: StageSpec
    params: Params

    @property
    def where(self) -> str:
        return f"stages[{self.index}].{self.spec.name}"


@dataclass(frozen=True)
class ReportCall:
    index: int
    name: str
    params: Params


@dataclass(frozen=True)
class Item:
    """One unit of work: one input file at one sweep point."""

    item_id: str
    input_path: str  # the primary input file (the mesh, the image, the fixed image of a pair)
    sweep: dict[str, Any]
    calls: tuple[StageCall, ...]
    input_label: str = ""  # the input as shown in tables ({bundled}/..., {data_root}/...)
    paths: dict[str, str] = field(default_factory=dict)  # state key -> file
    values: dict[str, Any] = field(default_factory=dict)  # state key -> value


@dataclass
class Experiment:
    """A validated config, ready to run."""

    raw: RawConfig
    source: Path | None
    calls: tuple[StageCall, ...]
    reports: tuple[ReportCall, ...]
    inputs: list[InputUnit] = field(default_factory=list)
    data_root: Path | None = None

    @property
    def name(self) -> str:
        return self.raw.name

    def sweep_points(self) -> list[dict[str, Any]]:
        """The sweep points, in config order: the Cartesian product of the sweep values (``grid``), or
        the baseline (every key at its first value) then one key at a time (``one_at_a_time``)."""
        keys = list(self.raw.sweep)
        if self.raw.sweep_mode == "grid":
            return [dict(zip(keys, combo)) for combo in itertools.product(*(self.raw.sweep[k] for k in keys))]
        baseline = {k: self.raw.sweep[k][0] for k in keys}
        return [baseline] + [{**baseline, k: v} for k in keys for v in self.raw.sweep[k][1:]]

    def items(self) -> list[Item]:
        """Every (input, sweep point) pair with its resolved stage calls."""
        out = []
        names = [u.primary.name for u in self.inputs]
        for unit in self.inputs:
            base = unit.primary.name if names.count(unit.primary.name) == 1 and len(unit.paths) == 1 else unit.label
            for point in self.sweep_points():
                calls = tuple(_with_overrides(self.calls, point))
                suffix = ",".join(f"{k}={v}" for k, v in point.items())
                item_id = base + (f"[{suffix}]" if suffix else "")
                out.append(Item(item_id, str(unit.primary), point, calls, unit.label,
                                {k: str(v) for k, v in unit.paths.items()}, dict(unit.values)))
        return out

    def resolved(self) -> dict[str, Any]:
        """The config with every default filled in (written to the run folder)."""
        return {
            "name": self.raw.name,
            "description": self.raw.description,
            "inputs": [{"label": u.label, **u.values} for u in self.inputs],
            "sweep": self.raw.sweep,
            "sweep_mode": self.raw.sweep_mode,
            "stages": [{c.spec.name: c.params.canonical()} for c in self.calls],
            "stage_versions": {c.spec.name: c.spec.version for c in self.calls},
            "reports": [{r.name: r.params.canonical()} for r in self.reports],
            "executor": self.raw.executor.model_dump(mode="json"),
            "figure_format": list(self.raw.figure_format),
            "dpi": self.raw.dpi,
        }

    def resolve_path(self, template: str, where: str) -> Path:
        """The one file a path template names ({bundled}, {data_root}, relative to the config's folder).

        Raises ConfigError / InputError naming ``where`` and the file.
        """
        base = self.source.parent if self.source else Path.cwd()
        return resolve_input(template, base_dir=base, root=self.data_root, where=where)[0]

    def content_hash(self) -> str:
        """Hash of what determines the results (not the executor), 12 hex digits."""
        payload = {k: v for k, v in self.resolved().items() if k != "executor"}
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:12]


def read_yaml(path: str | Path) -> dict[str, Any]:
    """Safe-load a YAML mapping; errors name the file."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "config file not found")
    if path.is_dir():
        raise InputError(path, "is a folder, not a config file: give the YAML file")
    if not path.is_file():  # a FIFO would block the read
        raise InputError(path, "not a regular file (a FIFO, socket or device): a config is a YAML text file")
    try:
        if path.stat().st_size > 4 * 2**20:
            raise ConfigError(f"{path}: config file larger than 4 MiB: refused")
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(path, f"cannot read config ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}): a config "
                          f"is a YAML text file") from None
    try:
        data = load_yaml(text)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: a config must be a YAML mapping, got {type(data).__name__}")
    return data


def apply_overrides(data: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply CLI ``--set key=value`` overrides to raw config data.

    ``key`` is either a dotted path into the config (``executor.kind``,
    ``name``), ``sweep.stage.param`` for a sweep (value: a list), or
    ``stage.param`` for a stage of the chain (``noise.sigma``); a param may
    be nested (``register.metric.alpha``). Values are parsed as YAML scalars
    (``0.01``, ``true``, ``[1, 2]``).
    """
    data = copy.deepcopy(data)
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set {item!r}: expected key=value")
        key, text = item.split("=", 1)
        try:
            value = load_yaml(text)
        except ConfigError as exc:
            raise ConfigError(f"--set {item!r}: the value is {exc}") from None
        parts = key.strip().split(".")
        if parts[0] == "sweep" and len(parts) >= 3:  # sweep keys contain a dot: sweep.<stage>.<param>
            _section(data, "sweep", dict, item)[".".join(parts[1:])] = value
            continue
        if parts[0] in RawConfig.model_fields:
            set_path(data, parts, value, f"--set {key}")
            continue
        if len(parts) < 2:
            raise ConfigError(f"--set {key}: expected a config key or stage.param")
        swept = data.get("sweep") if isinstance(data.get("sweep"), dict) else {}
        if key.strip() in swept:  # the sweep sets it at every point: a chain value would be silently ignored
            raise ConfigError(f"--set {key}: the config sweeps {key.strip()} over {swept[key.strip()]!r}, which sets it "
                              f"at every sweep point; set the sweep instead, e.g. --set 'sweep.{key.strip()}=[{text}]'")
        entries = _section(data, "stages", list, item)
        positions = [i for i, e in enumerate(entries) if _entry_name(e) == parts[0]]
        if len(positions) != 1:
            raise ConfigError(f"--set {key}: the chain has {len(positions)} stages called {parts[0]!r}, expected exactly one")
        i = positions[0]
        entry = entries[i]
        params = copy.deepcopy(dict(entry[parts[0]] or {})) if isinstance(entry, dict) else {}
        set_path(params, parts[1:], value, f"--set {key}")
        entries[i] = {parts[0]: params}
    return data


def _section(data: dict[str, Any], name: str, kind: type, item: str) -> Any:
    """``data[name]`` (created empty when absent or null) for ``--set item``; a ConfigError when it is not a ``kind``."""
    if data.get(name) is None:
        data[name] = kind()
    section = data[name]
    if not isinstance(section, kind):
        raise ConfigError(f"--set {item!r}: the config's {name!r} is a {type(section).__name__}, "
                          f"not a {'mapping' if kind is dict else 'list'}")
    return section


def _entry_name(entry: Any) -> str | None:
    if isinstance(entry, str):
        return entry
    if isinstance(entry, dict) and len(entry) == 1:
        return next(iter(entry))
    return None


def _split_entry(entry: Any, where: str) -> tuple[str, dict[str, Any]]:
    name = _entry_name(entry)
    if name is None:
        raise ConfigError(f"{where}: expected a stage name or a mapping {{name: {{params}}}} with one key, got {entry!r}")
    params = entry[name] if isinstance(entry, dict) else None
    return name, dict(params or {})


def build_experiment(
    data: dict[str, Any],
    *,
    source: Path | None = None,
    data_root: Path | None = None,
    resolve_inputs: bool = True,
) -> Experiment:
    """Validate raw config data into an :class:`Experiment`.

    Checks the structure, every stage name and parameter set, that each stage's
    inputs are produced earlier in the chain, every sweep key and value, every
    report, and (``resolve_inputs``) that the input files exist.
    """
    prefix = f"{source}: " if source else ""
    try:
        raw = validate_json_strict(RawConfig, data, "")
        calls = resolve_chain(raw.stages)
        given = {key for kind, keys in INPUT_STATE.items() if getattr(raw.inputs, kind) for key in keys}
        if not given and any(k in call.spec.consumes for call in calls for keys in INPUT_STATE.values() for k in keys):
            raise ConfigError("inputs: the chain reads input files, and the config lists none; give e.g. "
                              "inputs: {meshes: [\"{bundled}/meshes/*.off\"]}")
        check_chain(calls, given)
        _check_sweeps(raw, calls)
        raw.executor.check()
        reports = _resolve_reports(raw)
    except ConfigError as exc:
        raise ConfigError(prefix + str(exc).replace("\n", "\n" + " " * len(prefix))) from None
    experiment = Experiment(raw=raw, source=source, calls=calls, reports=reports)
    if resolve_inputs:
        base = source.parent if source else Path.cwd()
        try:
            paths = resolve_inputs_config(raw.inputs, base_dir=base, data_root=data_root)
        except ConfigError as exc:
            raise ConfigError(prefix + str(exc)) from None
        experiment.inputs = paths
        experiment.data_root = data_root
    return experiment


def resolve_inputs_config(inputs: InputsConfig, *, base_dir: Path, data_root: Path | None) -> list[InputUnit]:
    """Expand every kind of input into :class:`InputUnit` objects (files checked to exist)."""
    units: list[InputUnit] = []

    def one(template: str, where: str, base: Path = base_dir) -> list[Path]:
        return resolve_input(template, base_dir=base, root=data_root, where=where)

    for kind in ("meshes", "images"):
        seen: set[Path] = set()
        for i, template in enumerate(getattr(inputs, kind)):
            for p in one(template, f"inputs.{kind}[{i}]"):
                if p.resolve() not in seen:  # a file two entries (or overlapping globs) name is one input, not two
                    seen.add(p.resolve())
                    units.append(InputUnit(display_path(p, data_root), {"path": p}))
    for i, pair in enumerate(inputs.pairs):
        (fixed,) = one(pair.fixed, f"inputs.pairs[{i}].fixed")[:1]
        (moving,) = one(pair.moving, f"inputs.pairs[{i}].moving")[:1]
        units.append(InputUnit(pair.label or f"{fixed.name}|{moving.name}", {"fixed_path": fixed, "moving_path": moving},
                               {"truth": pair.truth}))
    if inputs.pairs_csv is not None:
        units += _pairs_from_csv(inputs.pairs_csv, one)
    return units


def _pairs_from_csv(spec: PairsCsvConfig, one) -> list[InputUnit]:
    """One pair per row of the pairs table; every problem of the table is an InputError naming it."""
    import csv

    (path,) = one(spec.path, "inputs.pairs_csv.path")[:1]
    if not path.is_file():
        raise InputError(path, "not a regular file: the pairs table is a CSV file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.DictReader(fh, strict=True))
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not a UTF-8 text file (byte {exc.start})") from None
    except csv.Error as exc:
        raise InputError(path, f"malformed CSV ({exc})") from None
    if not rows:
        raise InputError(path, "the pairs table has no rows")
    units = []
    for r, row in enumerate(rows):
        where = f"row {r + 2}"
        wanted = [spec.fixed_column, spec.moving_column, *spec.truth_columns.values()]
        missing = [c for c in wanted if c not in row]
        if missing:
            raise InputError(path, f"{where}: no column {missing[0]!r} (columns: {', '.join(map(str, row))})")
        short = any(row[c] is None for c in wanted)  # DictReader's marks: None values (short), a None key (long)
        if short or None in row:
            raise InputError(path, f"{where}: {'too few' if short else 'too many'} cells for the "
                                   f"{len(row) - (None in row)} columns of the header")
        cells = {name: row[col].strip() for name, col in spec.truth_columns.items()}
        if any(v == "" for v in cells.values()):
            if spec.skip_missing_truth:
                continue
            raise InputError(path, f"{where}: empty truth cell")
        try:
            truth = {name: float(v) for name, v in cells.items()} or None
        except ValueError as exc:
            raise InputError(path, f"{where}: truth is not a number ({exc})") from None
        if truth and not all(math.isfinite(v) for v in truth.values()):
            raise InputError(path, f"{where}: truth is not a finite number ({cells})")
        fixed = one(row[spec.fixed_column], f"{path}: {where} fixed", path.parent)[0]
        moving = one(row[spec.moving_column], f"{path}: {where} moving", path.parent)[0]
        units.append(InputUnit(f"{fixed.name}|{moving.name}", {"fixed_path": fixed, "moving_path": moving},
                               {"truth": truth}))
    if not units:
        raise InputError(path, "every row lacks its truth (skip_missing_truth): no pairs to register")
    return units


def load_experiment(
    path: str | Path,
    *,
    overrides: list[str] = (),
    data_root: Path | None = None,
    resolve_inputs: bool = True,
) -> Experiment:
    """Read, override and validate the config file at ``path``."""
    path = Path(path)
    data = apply_overrides(read_yaml(path), list(overrides))
    return build_experiment(data, source=path, data_root=data_root, resolve_inputs=resolve_inputs)


def resolve_chain(entries: list[Any] | tuple[Any, ...]) -> tuple[StageCall, ...]:
    """Stage calls (validated params, unique labels) of a chain in config form (names or {name: params})."""
    calls, seen = [], {}
    for i, entry in enumerate(entries):
        name, params = _split_entry(entry, f"stages[{i}]")
        try:
            spec = get_stage(name)
        except ConfigError as exc:
            raise ConfigError(f"stages[{i}]: {exc}") from None
        seen[name] = seen.get(name, 0) + 1
        label = name if seen[name] == 1 else f"{name}#{seen[name]}"
        calls.append(StageCall(i, label, spec, spec.params.parse(params, f"stages[{i}].{name}")))
    return tuple(calls)


def check_chain(calls: tuple[StageCall, ...], available: set[str]) -> None:
    """Check that every stage's consumed entries are ``available`` initially or produced earlier."""
    available = set(available)
    for call in calls:
        missing = [k for k in call.spec.consumes if k not in available]
        if missing:
            raise ConfigError(
                f"{call.where}: needs {', '.join(repr(m) for m in missing)}, which neither the inputs "
                f"nor an earlier stage provide (available: {', '.join(sorted(available)) or 'nothing'})"
            )
        available.update(call.spec.produces)


def chain_with(chain: list[Any] | tuple[Any, ...], overrides: dict[str, dict[str, Any]]) -> list[Any]:
    """``chain`` (config form) with ``overrides`` {stage name: {param: value}} merged into the one stage
    of each name (nested mappings are merged key by key)."""
    out = list(chain)
    for name, values in overrides.items():
        positions = [i for i, e in enumerate(out) if _entry_name(e) == name]
        if len(positions) != 1:
            raise ConfigError(f"the chain has {len(positions)} stages called {name!r}, expected exactly one")
        i = positions[0]
        entry = out[i]
        params = copy.deepcopy(dict(entry[name] or {})) if isinstance(entry, dict) else {}
        out[i] = {name: deep_merge(params, values)}
    return out


def _sweep_target(key: str, calls: tuple[StageCall, ...]) -> tuple[int, list[str]]:
    """(position in the chain, parameter path) of a sweep key ``stage.param`` or ``stage.group.param``."""
    if key.count(".") < 1:
        raise ConfigError(f"sweep.{key}: expected 'stage.param'")
    name, *path = key.split(".")
    matches = [i for i, c in enumerate(calls) if c.label == name]  # a label: 'decimate' is the first, 'decimate#2' ...
    if not matches:
        matches = [i for i, c in enumerate(calls) if c.spec.name == name]
    if len(matches) != 1:
        raise ConfigError(f"sweep.{key}: the chain has {len(matches)} stages called {name!r}, expected exactly one "
                          f"(name a repeated stage by its label: {name}#2, {name}#3, ...)")
    model: Any = calls[matches[0]].spec.params
    for depth, part in enumerate(path):
        fields = getattr(model, "model_fields", None)
        if fields is None or part not in fields:
            known = ", ".join(fields or {}) or "none"
            where = ".".join([name, *path[:depth]])
            raise ConfigError(f"sweep.{key}: {where!r} has no parameter {part!r} (parameters: {known})")
        model = _model_of(fields[part].annotation)
    return matches[0], path


def _model_of(annotation: Any) -> Any:
    """The pydantic model inside an annotation (``Model`` or ``Model | None``), else None."""
    import typing

    for candidate in (annotation, *typing.get_args(annotation)):
        if isinstance(candidate, type) and issubclass(candidate, BaseModel):
            return candidate
    return None


def _with_overrides(calls: tuple[StageCall, ...], point: dict[str, Any]) -> list[StageCall]:
    out = list(calls)
    for key, value in point.items():
        pos, path = _sweep_target(key, calls)
        call = out[pos]
        values = call.params.model_dump(mode="json")
        set_path(values, path, value, f"sweep.{key}")
        out[pos] = StageCall(call.index, call.label, call.spec, call.spec.params.parse(values, f"sweep.{call.spec.name}"))
    return out


def _check_sweeps(raw: RawConfig, calls: tuple[StageCall, ...]) -> None:
    for key, values in raw.sweep.items():
        _sweep_target(key, calls)
        for j, value in enumerate(values):
            try:
                _with_overrides(calls, {key: value})
            except ConfigError as exc:
                raise ConfigError(str(exc).replace(f"sweep.{key}", f"sweep.{key}[{j}]", 1)) from None


def _resolve_reports(raw: RawConfig) -> tuple[ReportCall, ...]:
    out = []
    for i, entry in enumerate(raw.reports):
        name, params = _split_entry(entry, f"reports[{i}]")
        try:
            spec = get_report(name)
        except ConfigError as exc:
            raise ConfigError(f"reports[{i}]: {exc}") from None
        out.append(ReportCall(i, name, spec.params.parse(params, f"reports[{i}].{name}")))
    return tuple(out)
