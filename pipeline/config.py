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

This module gathers the names of the modules that hold each idea, so that
``from topomatch.pipeline.config import ...`` keeps working:

- :mod:`~topomatch.pipeline.schema`: the config file's structure (``RawConfig``, ``ExecutorConfig``);
- :mod:`~topomatch.pipeline.yaml_loading`: reading a YAML file safely (``read_yaml``);
- :mod:`~topomatch.pipeline.overrides`: ``--set key=value`` (``apply_overrides``);
- :mod:`~topomatch.pipeline.inputs`: inputs -> files, through the input kinds the domains declare
  (``check_inputs``, ``resolve_inputs_config``; image pairs and their CSV table are
  :mod:`topomatch.stages.registration.inputs`);
- :mod:`~topomatch.pipeline.chain`: the stage chain and its check (``resolve_chain``, ``check_chain``, ``chain_with``);
- :mod:`~topomatch.pipeline.sweeps`: sweep points and their checks;
- :mod:`~topomatch.pipeline.experiment`: ``Experiment``, ``Item``, ``build_experiment``, ``load_experiment``.
"""

from __future__ import annotations

from topomatch.pipeline.chain import (
    ReportCall,
    StageCall,
    chain_with,
    check_chain,
    entry_name,
    resolve_chain,
    resolve_reports,
    split_entry,
)
from topomatch.pipeline.experiment import Experiment, Item, build_experiment, load_experiment
from topomatch.pipeline.inputs import InputFiles, InputUnit, check_inputs, given_state, resolve_inputs_config
from topomatch.pipeline.overrides import apply_overrides
from topomatch.pipeline.schema import (
    DEFAULT_DASK_TIMEOUT,
    MAX_SWEEP_POINTS,
    SCHEDULER_ENV,
    ExecutorConfig,
    RawConfig,
)
from topomatch.pipeline.sweeps import check_sweeps, sweep_points, sweep_target, with_overrides
from topomatch.pipeline.yaml_loading import read_yaml

__all__ = [
    "DEFAULT_DASK_TIMEOUT", "MAX_SWEEP_POINTS", "SCHEDULER_ENV", "ExecutorConfig", "Experiment",
    "InputFiles", "InputUnit", "Item", "RawConfig", "ReportCall", "StageCall",
    "apply_overrides", "build_experiment", "chain_with", "check_chain", "check_inputs", "check_sweeps", "entry_name",
    "given_state",
    "load_experiment", "read_yaml", "resolve_chain", "resolve_inputs_config", "resolve_reports", "split_entry",
    "sweep_points", "sweep_target", "with_overrides",
]
