"""Experiment configs: the Python API behind ``topomatch run | validate | configs``.

A config path that does not exist is also looked up among the configs installed with the package
(``configs/demo.yaml``, ``retrieval/demo``, ...), so ``topomatch run configs/demo.yaml`` works from
any folder after ``pip install``.
"""

from __future__ import annotations

from pathlib import Path

from topomatch.pipeline.config import Experiment, load_experiment
from topomatch.pipeline.errors import InputError
from topomatch.pipeline.paths import data_root
from topomatch.pipeline.runner import DEFAULT_OUT, RunOutcome, run_experiment

#: The configs installed with the package (the repository's configs/ folder).
CONFIGS_DIR = Path(__file__).resolve().parent.parent / "configs"
if not CONFIGS_DIR.is_dir():  # an installed package: topomatch/configs
    CONFIGS_DIR = Path(__file__).resolve().parent / "configs"


def bundled_configs() -> list[Path]:
    """Every installed config file, sorted."""
    return sorted(CONFIGS_DIR.rglob("*.yaml"))


def find_config(path: str | Path) -> Path:
    """``path`` if it exists, else the installed config it names (``configs/demo.yaml``, ``demo.yaml``,
    ``retrieval/demo``).

    Raises
    ------
    InputError
        Neither exists (the message lists where it looked).
    """
    path = Path(path)
    if path.exists():
        return path
    rel = Path(*path.parts[1:]) if path.parts and path.parts[0] == "configs" else path
    for candidate in (CONFIGS_DIR / rel, CONFIGS_DIR / rel.with_suffix(".yaml")):
        if candidate.is_file():
            return candidate
    raise InputError(path, f"config file not found (nor among the installed configs in {CONFIGS_DIR}; "
                           f"`topomatch configs` lists them)")


def load_config(path: str | Path, *, overrides: list[str] = (), data_root_dir: str | Path | None = None) -> Experiment:
    """Read, override (``stage.param=value``) and validate a config; input files are checked to exist.

    Raises ConfigError / InputError naming the file and the problem.
    """
    return load_experiment(find_config(path), overrides=list(overrides), data_root=data_root(data_root_dir))


def run_config(path: str | Path, *, overrides: list[str] = (), out: str | Path = DEFAULT_OUT,
               data_root_dir: str | Path | None = None, cache_dir: str | Path | None = None, use_cache: bool = True,
               progress: bool = False) -> RunOutcome:
    """Run a config and write its run folder under ``out``; returns where, and each item's results.

    Failed items do not raise: see ``RunOutcome.failed`` (the other items' results are written).
    """
    experiment = load_config(path, overrides=overrides, data_root_dir=data_root_dir)
    return run_experiment(experiment, out_root=out, cache_dir=cache_dir, use_cache=use_cache, progress=progress)
