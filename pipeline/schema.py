"""The config file's structure, as pydantic models: what keys a config may have and their types.

:class:`RawConfig` is a config file before its stage names, parameters and input kinds are resolved
(:mod:`topomatch.pipeline.experiment` does that; the kinds of input are declared by the domains,
:mod:`topomatch.pipeline.inputs`). Every model is strict and rejects unknown keys, so
``"5"`` is not an int and a misspelt key is an error with its path.
"""

from __future__ import annotations

import math
import os
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from topomatch.pipeline.errors import ConfigError


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


#: Most sweep points a config may ask for (a grid's size is the product of its value counts).
MAX_SWEEP_POINTS = 10_000


class RawConfig(_Strict):
    """The structure of a config file, before stage names and params are resolved."""

    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
    description: str = ""
    inputs: dict[str, Any] = Field(
        default_factory=dict, description="input kind -> its value, e.g. {meshes: [templates]}; each kind is declared "
                                          "by a domain (pipeline/inputs.py) and checks its own value")
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
