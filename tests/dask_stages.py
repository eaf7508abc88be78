"""Stages for the dask tests, in a module of their own so that a dask worker started as a separate process
(``dask worker``, with ``tests/`` on its ``PYTHONPATH``) can import them: a task names its stage function
by module and name, as a user's stage module must be importable on every worker (docs/cluster.md)."""

from __future__ import annotations

import dataclasses
import os
import sys
import time

from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.pipeline.registry import register_module


class ExitParams(Params):
    exit_on: str = Field("", description="end the worker process (os._exit) on the mesh of this name")
    sleep: float = Field(0.0, ge=0, description="seconds to sleep first")


@dataclasses.dataclass(frozen=True)
class Seen(StageResult):
    name: str

    def summary(self) -> dict:
        return {"name": self.name}


@stage("test_worker_exit", params=ExitParams, version=1, consumes=("mesh",), produces=())
def worker_exit(mesh, *, params) -> Seen:
    """Test stage: sleeps, then ends its process without a word on one mesh (as a crash in native code does)."""
    time.sleep(params.sleep)
    if mesh.name == params.exit_on:
        os._exit(3)
    return Seen(mesh.name)


# registered on import: in the test process, and in a worker when it unpickles the first task naming this module
# (so that the worker's cache stores this module's results too)
register_module(sys.modules[__name__])


def blas_threads() -> list[int]:
    """The thread counts of the BLAS libraries loaded in this process (numpy's and scipy's own OpenBLAS)."""
    import scipy.sparse.linalg  # noqa: F401  (what the stages use: scipy's own OpenBLAS)
    from threadpoolctl import threadpool_info

    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
