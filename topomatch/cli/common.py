"""What the command modules share: declaring a command whose options are built only when it runs,
the global verbosity (``-v``/``-q``), messages on stderr, and printing a result as one JSON object
(``--json``, the schema in ``topomatch/cli/schema.json``) or aligned ``key: value`` lines."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Callable, Iterable

#: The JSON Schema of every command's ``--json`` output and of the error object (docs/cli_json.md).
SCHEMA_PATH = Path(__file__).with_name("schema.json")


class _State:
    """Per-invocation state of the command line, reset by :func:`topomatch.cli.main`."""

    verbosity = 0  # -1 quiet (errors only), 0 normal, 1 verbose (-v), 2 debug logging (-vv)
    json_printed = False  # a --json result object is already on stdout (an error then goes to stderr only)


STATE = _State()


def reset(verbosity: int = 0) -> None:
    """Start an invocation with ``verbosity`` and no JSON printed yet."""
    STATE.verbosity = verbosity
    STATE.json_printed = False


def verbosity() -> int:
    """-1 with ``-q``, 0 by default, 1 with ``-v``, 2 with ``-vv``."""
    return STATE.verbosity


def info(message: str, *, level: int = 0) -> None:
    """Print ``message`` on stderr when the verbosity is at least ``level`` (0: unless ``-q``; 1: ``-v``)."""
    if STATE.verbosity >= level:
        print(message, file=sys.stderr)


def warn(message: str) -> None:
    """``topomatch: warning: message`` on stderr, unless ``-q``."""
    info(f"topomatch: warning: {message}", level=0)


def add_verbosity_options(p: argparse.ArgumentParser, *, default: Any = argparse.SUPPRESS) -> None:
    """``-v/--verbose`` (repeatable) and ``-q/--quiet``: accepted before the command and after it."""
    p.add_argument("-v", "--verbose", action="count", default=default,
                   help="say more on stderr: every output file, per-stage times; -vv adds debug logging")
    p.add_argument("-q", "--quiet", action="store_true", default=default,
                   help="print only the result and errors: no progress bars, notes or warnings")


def command(sub, name: str, *, help: str, description: str, handler: Callable[[argparse.Namespace], int],
            build: Callable[[argparse.ArgumentParser], None]) -> None:
    """Add the subcommand ``name``; ``build(parser)`` adds its arguments, only when the command line
    asks for this command (or for all, ``sub.selected is None``): building options from the params
    models imports the stages, which ``topomatch --help`` and the other commands need not pay for."""
    p = sub.add_parser(name, help=help, description=description)
    p.set_defaults(handler=handler)
    add_verbosity_options(p)
    if getattr(sub, "selected", None) in (None, name):
        build(p)


def _executor_options() -> tuple:
    """The executor settings a command that fans out work exposes, as options of its command line."""
    from topomatch.pipeline.cli_options import Option

    return (Option("executor.kind", flag="--executor"),
            Option("executor.address"),
            Option("executor.workers", default_help="all cores"),
            Option("executor.timeout", flag="--dask-timeout"))


def add_executor_options(p: argparse.ArgumentParser) -> None:
    """``--executor local|dask``, ``--address``, ``--workers``, ``--dask-timeout``: generated from the config's
    executor settings (:class:`~topomatch.pipeline.config.ExecutorConfig`), the same for every command that
    fans out work (``run``, ``validate``, ``index``). Given, they take precedence over the config's
    ``executor:`` and ``--set executor.*``; ``--address`` over ``$DASK_SCHEDULER_ADDRESS``."""
    from topomatch.pipeline.cli_options import add_options
    from topomatch.pipeline.config import ExecutorConfig

    group = p.add_argument_group("executor", "where the work runs (docs/cluster.md); settings that do not apply to "
                                             "the chosen executor are refused")
    add_options(group, {"executor": ExecutorConfig}, _executor_options())


def executor_options(args: argparse.Namespace) -> dict[str, Any]:
    """The executor settings given on the command line (``{"kind": "dask", "address": ...}``), each validated.

    Raises
    ------
    ConfigError
        A value its setting refuses (``--workers 0``), naming the option.
    """
    from topomatch.pipeline.cli_options import given_options
    from topomatch.pipeline.config import ExecutorConfig

    return given_options(args, {"executor": ExecutorConfig}, _executor_options()).get("executor", {})


def describe_os_error(exc: OSError) -> str:
    """``path: problem`` for a file-system error, in a user's words."""
    where = exc.filename or ""
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        problem = f"a file is in the way of a folder to write into ({exc.strerror}); choose another path"
    elif isinstance(exc, PermissionError):
        problem = "permission denied"
    else:
        problem = exc.strerror or str(exc)
    return f"{where}: {problem}" if where else problem


def path_argument(text: str) -> str:
    """An argparse type for a path option: refuses the empty string (which would silently mean
    'the current folder' or 'no output')."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path; give a file or folder name")
    return text


def input_path(text: str) -> str:
    """An argparse type for an input file or folder: refuses the empty string, and turns ``bundled:NAME`` into
    the path of the bundled data file (or folder) it names (:func:`topomatch.data_path`), so the examples work
    from any folder. Every command's input arguments use it: this is where the command line resolves them.

    Raises
    ------
    InputError
        ``bundled:NAME`` names nothing bundled (the message lists the closest bundled files); the command
        exits with 1, as for any missing input (:func:`topomatch.cli.main`).
    """
    from topomatch.pipeline.paths import BUNDLED_PREFIX, data_path

    path_argument(text)
    return str(data_path(text)) if text.startswith(BUNDLED_PREFIX) else text


def _finite(value: Any) -> Any:
    """``value`` with every NaN or infinite float replaced by None (JSON has no NaN)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def to_json(value: Any, **kwargs) -> str:
    """Strict JSON text of ``value``: NaN and infinities become null, never the invalid ``NaN``."""
    return json.dumps(_finite(value), allow_nan=False, **kwargs)


def print_json(value: Any, **kwargs) -> None:
    """Print a command's ``--json`` result (one object on stdout)."""
    print(to_json(value, **kwargs))
    STATE.json_printed = True


def print_result(summary: dict[str, Any], *, as_json: bool, keys: Iterable[str] | None = None) -> None:
    """Print ``summary`` as one JSON object, or as ``key: value`` lines (only ``keys``, in their order,
    leaving out empty values, when given)."""
    if as_json:
        print_json(summary)
        return
    shown = [k for k in (keys or summary) if k in summary and summary[k] not in ("", None, [])]
    width = max((len(k) for k in shown), default=0)
    for key in shown:
        print(f"{key:>{width}}: {summary[key]}")


def error_file(exc: BaseException, message: str) -> str | None:
    """The file an error is about: the exception's own (``InputError.path``, ``OSError.filename``), else
    the ``path`` of a ``path: problem`` message when that path exists or looks like a file name."""
    for attr in ("path", "filename"):
        value = getattr(exc, attr, None)
        if value:
            return str(value)
    head = message.split(": ", 1)[0] if ": " in message else ""
    if head and " " not in head and (Path(head).exists() or "/" in head or Path(head).suffix):
        return head
    return None


def error_object(message: str, *, status: int, kind: str, file: str | None = None) -> dict[str, Any]:
    """The ``--json`` error object: ``error`` (the message), ``file`` (or null), ``status`` (the exit
    status) and ``kind`` (``usage``, ``config``, ``input``, ``stage``, ``run``, ``os``, ``interrupted``,
    ``error``)."""
    return {"error": message, "file": file, "status": status, "kind": kind}
