"""``topomatch register FIXED MOVING``: rigid registration of two images or two volumes, without a config file.

Two 2D images (or slices: ``--fixed-slice`` / ``--moving-slice``) or two 3D volumes (NIfTI, MetaImage,
NRRD, DICOM file or series folder), the same command: options come from the ``load_pair`` and ``register``
params (:data:`topomatch.registration.REGISTER_OPTIONS`); the summary or ``--json`` object is
:class:`topomatch.registration.RegistrationOutcome`'s fields (the parameters, centre and homogeneous
fixed-to-moving ``matrix`` in physical units). With ``--out DIR`` it also writes the moving image resampled
onto the fixed grid, ``transform.tfm``, an overlay figure and ``registration.json``
(:func:`topomatch.registration.write_registration_files`).

Exit status: 0 when the registration passed its self-check, 1 when it was flagged (the result is
still printed, with the reason), 1 for unreadable or unusable images, 2 for bad options.
"""

from __future__ import annotations

import argparse

from topomatch.cli.common import command, describe_os_error, info, input_path, path_argument, print_result
from topomatch.pipeline.cli_options import Option, add_options, add_set_option, given_options, set_options
from topomatch.pipeline.errors import InputError, TopomatchError
from topomatch.pipeline.files import check_writable_folder


class RegistrationFlagged(TopomatchError):
    """The registration ran but failed its self-check (the result was printed)."""


def _models() -> dict:
    from topomatch.stages.registration.io import LoadPairParams
    from topomatch.stages.registration.params import RegisterParams

    return {"load_pair": LoadPairParams, "register": RegisterParams}


def _options() -> list[Option]:
    from topomatch.registration import REGISTER_OPTIONS

    return list(REGISTER_OPTIONS.values())


def add_parsers(sub) -> None:
    command(sub, "register", help="rigidly register a moving image to a fixed image",
            description="Rigid registration of MOVING to FIXED, two 2D images or two 3D volumes, by an entropic "
                        "measure (Jensen-Tsallis by default, thesis ch. 2) with coarse-to-fine SPSA, in ITK's "
                        "convention: T(p) = R (p - c) + c + t on physical points (column, row pixels for a PNG; LPS mm "
                        "for a volume), c = the centre of FIXED's grid, moving(T(p)) ~ fixed(p). Prints SimpleITK's "
                        "Euler2D parameters (2D: tx, ty, angle in degrees) or Euler3D parameters (3D: angles, "
                        "translation), the centre and the homogeneous fixed-to-moving matrix.",
            handler=cmd_register, build=_arguments)


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("fixed", type=input_path, help="fixed (reference) image or volume: PNG, TIFF, NIfTI, DICOM (file or "
                                                  "series folder), MetaImage, NRRD; bundled:NAME for a bundled one")
    p.add_argument("moving", type=input_path, help="moving (target) image or volume")
    add_options(p, _models(), _options())
    add_set_option(p, _models(), "register")
    p.add_argument("--out", type=path_argument, metavar="DIR", help="write the moving image resampled on the fixed grid "
                   "(moving_resampled in the moving file's format; PNG also as a float32 .tif), transform.tfm, "
                   "overlay.png and registration.json")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def _mixed_conventions(fixed, moving) -> str:
    """A hint when one input is a Pillow format (pixel units, rows down) and the other a medical one (its header's
    physical frame): the same pixels need not lie in the same place (a NIfTI's identity affine is a 180-degree turn)."""
    from pathlib import Path

    from topomatch.stages.imaging.files import PILLOW_SUFFIXES

    pillow = [not Path(p).is_dir() and Path(p).name.lower().endswith(PILLOW_SUFFIXES) for p in (fixed, moving)]
    if pillow[0] == pillow[1]:
        return ""
    return (f" (note: {'the fixed' if pillow[0] else 'the moving'} image is a PNG/TIFF/JPEG/BMP in pixel units with "
            f"rows down, the other places its pixels by its header, in millimetres: the same pixels in the two formats "
            f"can look flipped or turned by 180 degrees; write both in one format, or copy the geometry)")


def cmd_register(args: argparse.Namespace) -> int:
    from topomatch.registration import check_outputs_spare_inputs, register_with, write_registration_files

    if args.out:
        check_writable_folder(args.out)  # before the registration runs, not after
        check_outputs_spare_inputs(args.out, args.fixed, args.moving)
    options = set_options(given_options(args, _models(), _options()), args.set_values, _models(), "register")
    outcome = register_with(args.fixed, args.moving, options)
    summary, unwritten = outcome.to_dict(), None
    if args.out:
        try:
            summary["files"] = write_registration_files(outcome, args.out)
        except (OSError, InputError) as exc:  # printed after the result: a failed write loses nothing computed
            unwritten = exc
            summary["files"] = getattr(exc, "written", [])  # the files that were written
            summary["unwritten"] = str(exc) if isinstance(exc, InputError) else describe_os_error(exc)
    keys = (("tx", "ty", "angle") if outcome.dimension == 2 else ("angles", "translation")) + (
        "center", "matrix", "objective", "overlap", "iterations", "seconds", "ok", "reason", "method", "files",
        "unwritten")
    print_result(summary, as_json=args.json, keys=keys)
    reg = outcome.registration
    info(f"  register: {reg.seconds:.2f} s, {reg.iterations} iterations, {reg.evaluations} evaluations", level=1)
    for path in summary.get("files", []):
        info(f"  output: {path}", level=1)
    if unwritten is not None:
        raise unwritten
    if not outcome.ok:
        raise RegistrationFlagged(f"registration flagged: {outcome.reason}{_mixed_conventions(args.fixed, args.moving)}")
    return 0
