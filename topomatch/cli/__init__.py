"""The ``topomatch`` command line: the engine's commands and each domain's.

``run``, ``validate``, ``stages``, ``configs`` (:mod:`.engine`); ``skeleton`` (:mod:`.skeleton`);
``match``, ``index``, ``query``, ``evaluate`` (:mod:`.retrieval`); ``register`` (:mod:`.registration`);
``thesis`` (:mod:`.thesis`).
Each command is a thin layer over the Python API (:mod:`topomatch`), with its options generated
from the params models (:mod:`topomatch.pipeline.cli_options`). Errors print one short message
naming the file and the problem and exit non-zero: 2 for a bad config or usage, 1 for bad input
data, a file that cannot be written, failed items or a flagged registration, 130 when interrupted;
``--debug`` shows the traceback instead. With ``--json`` stdout holds exactly one JSON object: the
result, or, when the command failed before printing one, the error object
(:func:`topomatch.cli.common.error_object`; docs/cli_json.md). ``-v``/``-q`` set how much goes to
stderr (:mod:`topomatch.cli.common`).
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings

from topomatch import __version__
from topomatch.cli import common, engine, registration, retrieval, skeleton, thesis
from topomatch.cli.allocator import keep_freed_memory
from topomatch.cli.common import describe_os_error
from topomatch.pipeline.errors import TopomatchError

#: The command modules, in --help order; each has ``add_parsers(subparsers)``.
COMMANDS = (engine, skeleton, retrieval, registration, thesis)


class Parser(argparse.ArgumentParser):
    """argparse's parser whose usage errors, when the command line asks for ``--json``, also print the
    JSON error object on stdout (the subcommands' parsers are of this class too)."""

    json_errors = False

    def error(self, message: str):
        if Parser.json_errors:
            self.print_usage(sys.stderr)
            print(f"{self.prog}: error: {message}", file=sys.stderr)
            print(common.to_json(common.error_object(f"{self.prog}: {message}", status=2, kind="usage")))
            self.exit(2)
        super().error(message)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command; with ``command``, only that command's arguments are built (the
    others are listed by name), which keeps ``topomatch --help`` and each command's start-up cheap."""
    parser = Parser(
        prog="topomatch",
        description="Topological shape skeletons, shape matching and retrieval, and entropic image "
                    "registration, run as reproducible YAML experiments.",
    )
    parser.add_argument("--version", action="version", version=f"topomatch {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    common.add_verbosity_options(parser, default=None)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    sub.selected = command  # read by topomatch.cli.common.command
    for module in COMMANDS:
        module.add_parsers(sub)
    return parser


def _command_name(argv: list[str]) -> str:
    """The command named on the command line ("" when none is: the top-level help or usage)."""
    for arg in argv:
        if not arg.startswith("-"):
            return arg
    return ""


def _fail(args: argparse.Namespace, message: str, status: int, kind: str, exc: BaseException | None) -> int:
    """Report an error: one line on stderr, and with ``--json`` the error object on stdout (unless the
    command already printed its result object, which then tells what went wrong)."""
    print(f"topomatch: {'error: ' if kind != 'interrupted' else ''}{message}", file=sys.stderr)
    if getattr(args, "json", False) and not common.STATE.json_printed:
        print(common.to_json(common.error_object(message, status=status, kind=kind,
                                                 file=common.error_file(exc, message) if exc else None)))
    return status


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so that Python's final flush does not fail on a closed pipe again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # no real file descriptor (a test's captured stdout)
        pass


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Python warnings (e.g. a cache entry that cannot be read) as the CLI's own: ``topomatch: warning: ...``,
    hidden by ``-q``; the source line only with ``-vv``."""
    where = f" ({category.__name__} at {filename}:{lineno})" if common.verbosity() >= 2 else ""
    common.warn(f"{message}{where}")


def main(argv: list[str] | None = None) -> int:
    command_line = argv is None
    if command_line:  # the command (not a call from Python): large numpy temporaries reuse freed memory
        keep_freed_memory()
    argv = sys.argv[1:] if argv is None else list(argv)
    Parser.json_errors = "--json" in argv
    common.reset()
    try:
        args = build_parser(_command_name(argv)).parse_args(argv)
    except TopomatchError as exc:  # an input argument that names nothing (bundled:NAME, common.input_path): status 1
        if "--debug" in argv:
            raise
        return _fail(argparse.Namespace(json=Parser.json_errors), str(exc), exc.exit_code, exc.kind, exc)
    level = -1 if args.quiet else (args.verbose or 0)
    common.reset(level)
    logging.basicConfig(format="topomatch: %(levelname)s: %(name)s: %(message)s",
                        level=logging.ERROR if level < 0 else logging.WARNING)  # other libraries: warnings only
    logging.getLogger("topomatch").setLevel({-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO}.get(
        level, logging.DEBUG))
    if command_line:  # not in a caller's process (a test recording warnings keeps Python's own display)
        warnings.showwarning = _show_warning
    try:
        return args.handler(args)
    except BrokenPipeError:  # the reader of stdout left (`topomatch ... --json | head`): stop quietly
        _silence_stdout()
        return 141  # 128 + SIGPIPE, as a shell reports a command killed by a closed pipe
    except TopomatchError as exc:
        if args.debug:
            raise
        return _fail(args, str(exc), exc.exit_code, exc.kind, exc)
    except OSError as exc:  # a file that cannot be written or read where the command put it (--out, --db, ...)
        if args.debug:
            raise
        return _fail(args, describe_os_error(exc), 1, "os", exc)
    except KeyboardInterrupt:
        return _fail(args, "interrupted; finished stages are cached, run again to resume", 130, "interrupted", None)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
