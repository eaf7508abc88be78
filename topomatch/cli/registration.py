"""``topomatch register FIXED MOVING``: rigid registration of two images, without a config file.

Options come from the ``load_pair`` and ``register`` params (:data:`topomatch.registration.REGISTER_OPTIONS`);
the summary or ``--json`` object is :class:`topomatch.registration.RegistrationOutcome`'s fields.
With ``--out DIR`` it also writes the moving image resampled onto the fixed grid, an overlay
figure and ``registration.json`` (:func:`topomatch.registration.write_registration_files`).

Exit status: 0 when the registration passed its self-check, 1 when it was flagged (the result is
still printed, with the reason), 1 for unreadable or unusable images, 2 for bad options.
"""

from __future__ import annotations

import argparse

from topomatch.cli.common import command, path_argument, print_result
from topomatch.pipeline.cli_options import Option, add_options, given_options
from topomatch.pipeline.errors import TopomatchError


class RegistrationFlagged(TopomatchError):
    """The registration ran but failed its self-check (the result was printed)."""


def _models() -> dict:
    from topomatch.stages.registration.io import LoadPairParams
    from topomatch.stages.registration.register import RegisterParams

    return {"load_pair": LoadPairParams, "register": RegisterParams}


def _options() -> list[Option]:
    from topomatch.registration import REGISTER_OPTIONS

    return list(REGISTER_OPTIONS.values())


def add_parsers(sub) -> None:
    command(sub, "register", help="rigidly register a moving image to a fixed image",
            description="Rigid 2D registration (tx, ty, angle) of MOVING to FIXED by an entropic measure "
                        "(Jensen-Tsallis by default, thesis ch. 2) with coarse-to-fine SPSA. Prints the transform "
                        "in ITK's convention: T(x) = R(angle)(x - c) + c + t, x = (column, row) pixels, "
                        "c = ((W-1)/2, (H-1)/2) of FIXED, moving(T(x)) ~ fixed(x).",
            handler=cmd_register, build=_arguments)


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("fixed", help="fixed (reference) image: PNG, TIFF, NIfTI, DICOM, MetaImage")
    p.add_argument("moving", help="moving (target) image")
    add_options(p, _models(), _options())
    p.add_argument("--out", type=path_argument, metavar="DIR", help="write moving_resampled.png/.tif, overlay.png and registration.json")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def cmd_register(args: argparse.Namespace) -> int:
    from topomatch.registration import register_with, write_registration_files

    outcome = register_with(args.fixed, args.moving, given_options(args, _models(), _options()))
    summary = outcome.to_dict()
    if args.out:
        summary["files"] = write_registration_files(outcome, args.out)
    print_result(summary, as_json=args.json, keys=("tx", "ty", "angle", "objective", "iterations", "seconds", "ok",
                                                   "reason", "method", "center", "files"))
    if not outcome.ok:
        raise RegistrationFlagged(f"registration flagged: {outcome.reason}")
    return 0
