"""The ``topomatch`` command line: the engine's commands and each domain's.

``run``, ``validate``, ``stages``, ``configs`` (:mod:`.engine`); ``skeleton`` (:mod:`.skeleton`);
``match``, ``index``, ``query``, ``evaluate`` (:mod:`.retrieval`); ``register`` (:mod:`.registration`).
Each command is a thin layer over the Python API (:mod:`topomatch`), with its options generated
from the params models (:mod:`topomatch.pipeline.cli_options`). Errors print one short message
naming the file and the problem and exit non-zero: 2 for a bad config or usage, 1 for bad input
data, a file that cannot be written, failed items or a flagged registration, 130 when interrupted;
``--debug`` shows the traceback instead.
"""

from __future__ import annotations

import argparse
import sys

from topomatch import __version__
from topomatch.cli import engine, registration, retrieval, skeleton
from topomatch.pipeline.errors import TopomatchError

#: The command modules, in --help order; each has ``add_parsers(subparsers)``.
COMMANDS = (engine, skeleton, retrieval, registration)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``command``, only that command's arguments are built (the
    others are listed by name), which keeps ``topomatch --help`` and each command's start-up cheap."""
    parser = argparse.ArgumentParser(
        prog="topomatch",
        description="Topological shape skeletons, shape matching and retrieval, and entropic image "
                    "registration, run as reproducible YAML experiments.",
    )
    parser.add_argument("--version", action="version", version=f"topomatch {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    sub.selected = command  # read by topomatch.cli.common.command
    for module in COMMANDS:
        module.add_parsers(sub)
    return parser


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


def _command_name(argv: list[str]) -> str:
    """The command named on the command line ("" when none is: the top-level help or usage)."""
    for arg in argv:
        if not arg.startswith("-"):
            return arg
    return ""


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(_command_name(argv)).parse_args(argv)
    try:
        return args.handler(args)
    except TopomatchError as exc:
        if args.debug:
            raise
        print(f"topomatch: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # a file that cannot be written or read where the command put it (--out, --db, ...)
        if args.debug:
            raise
        print(f"topomatch: error: {describe_os_error(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("topomatch: interrupted; finished stages are cached, run again to resume", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
