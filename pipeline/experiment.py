"""A validated config, ready to run: :class:`Experiment` (its stage calls, reports, inputs and sweep points)
and its :class:`Item` objects (one input at one sweep point), built from raw data (:func:`build_experiment`)
or a YAML file with ``--set`` overrides (:func:`load_experiment`)."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from topomatch.pipeline.chain import ReportCall, StageCall, check_chain, resolve_chain, resolve_reports
from topomatch.pipeline.errors import ConfigError
from topomatch.pipeline.inputs import InputFiles, InputUnit, check_inputs, given_state, resolve_inputs_config
from topomatch.pipeline.overrides import apply_overrides
from topomatch.pipeline.registry import get_input
from topomatch.pipeline.params import validate_json_strict
from topomatch.pipeline.schema import RawConfig
from topomatch.pipeline.sweeps import check_sweeps, sweep_points, with_overrides
from topomatch.pipeline.yaml_loading import read_yaml


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
        """The sweep points, in config order (:func:`~topomatch.pipeline.sweeps.sweep_points`)."""
        return sweep_points(self.raw)

    def items(self) -> list[Item]:
        """Every (input, sweep point) pair with its resolved stage calls."""
        out = []
        names = [u.primary.name for u in self.inputs]
        for unit in self.inputs:
            base = unit.primary.name if names.count(unit.primary.name) == 1 and len(unit.paths) == 1 else unit.label
            for point in self.sweep_points():
                calls = tuple(with_overrides(self.calls, point))
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
        return InputFiles(self.source.parent if self.source else Path.cwd(), self.data_root).one(template, where)

    def content_hash(self) -> str:
        """Hash of what determines the results (not the executor), 12 hex digits."""
        payload = {k: v for k, v in self.resolved().items() if k != "executor"}
        return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:12]


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
        inputs = check_inputs(raw.inputs, get_input)
        given = given_state(inputs)
        if not given:
            raise ConfigError("inputs: the chain reads input files, and the config lists none; give e.g. "
                              "inputs: {meshes: [\"{bundled}/meshes/*.off\"]}")
        check_chain(calls, given)
        check_sweeps(raw, calls)
        raw.executor.check()
        reports = resolve_reports(raw.reports)
    except ConfigError as exc:
        raise ConfigError(prefix + str(exc).replace("\n", "\n" + " " * len(prefix))) from None
    experiment = Experiment(raw=raw, source=source, calls=calls, reports=reports)
    if resolve_inputs:
        base = source.parent if source else Path.cwd()
        try:
            paths = resolve_inputs_config(inputs, base_dir=base, data_root=data_root)
        except ConfigError as exc:
            raise ConfigError(prefix + str(exc)) from None
        experiment.inputs = paths
        experiment.data_root = data_root
    return experiment


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
