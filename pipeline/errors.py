"""Exception types of the project.

Every error a user can cause (bad config, bad mesh, bad image, bad CLI use) is a
:class:`TopomatchError`; the CLI prints its message and exits non-zero, with a
traceback only under ``--debug``. Never use ``assert`` for input checks.
"""

from __future__ import annotations

from pathlib import Path


class TopomatchError(Exception):
    """Base class of the errors the CLI reports as a short message (``kind``: the ``--json`` error's kind)."""

    exit_code = 1
    kind = "error"


class ConfigError(TopomatchError):
    """A malformed or invalid experiment config, CLI override or parameter set."""

    exit_code = 2
    kind = "config"


class InputError(TopomatchError):
    """An input file that cannot be used (missing, unreadable, malformed, degenerate).

    The message always names the file.
    """

    kind = "input"

    def __init__(self, path: str | Path | None, problem: str):
        self.path = None if path is None else str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}" if self.path else problem)


class StageError(TopomatchError):
    """A stage that cannot produce a result for a valid input (e.g. a solver failure)."""

    kind = "stage"


class RunError(TopomatchError):
    """A run that finished with failed items; the results of the others were written."""

    kind = "run"


class ExecutorError(TopomatchError):
    """The executor could not finish a run: the dask scheduler was lost or unreachable mid-run, or it has no
    workers. What finished is kept (cached stages, indexed rows): the same command resumes."""

    kind = "executor"


class InputWarning(UserWarning):
    """An input was read under an assumption the file does not state (e.g. a NIfTI header without an
    orientation); the CLI prints it as ``topomatch: warning: ...``."""
