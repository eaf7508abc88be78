"""``topomatch register FIXED MOVING``: rigid registration of two images, without a config file.

Runs the stage chain load_pair -> register through the same item runner as ``topomatch run``
(no cache) and prints the transform in ITK's convention (``T(x) = R(angle)(x - c) + c + t``,
x = (column, row) in pixels, c the fixed image's centre, ``moving(T(x)) ~ fixed(x)``), the final
objective, iterations and seconds, or one JSON object with ``--json``. With ``--out DIR`` it also
writes the moving image resampled onto the fixed grid (``moving_resampled.png`` 8-bit and
``moving_resampled.tif`` float32), ``overlay.png`` (fixed, moving, checkerboards before and
after, colour overlay) and ``registration.json`` (the summary and the optimiser's history).

Exit status: 0 when the registration passed its self-check, 1 when it was flagged (the result is
still printed, with the reason), 1 for unreadable or unusable images, 2 for bad options.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from topomatch.pipeline.errors import InputError, StageError, TopomatchError


class RegistrationFlagged(TopomatchError):
    """The registration ran but failed its self-check (the result was printed)."""


def register_config(fixed: Path, moving: Path, args: argparse.Namespace) -> dict:
    """The equivalent experiment config."""
    load = {k: v for k, v in {"fixed_slice": args.fixed_slice, "moving_slice": args.moving_slice}.items()
            if v is not None}
    reg = {"metric": args.metric, "alpha": args.alpha, "weights": args.weights, "optimizer": args.optimizer,
           "seed": args.seed}
    return {
        "name": "register",
        "inputs": {"pairs": [{"fixed": str(fixed), "moving": str(moving)}]},
        "stages": [{"load_pair": load}, {"register": reg}],
        "executor": {"kind": "local", "workers": 1},
    }


def add_parser(sub) -> None:
    p = sub.add_parser("register", help="rigidly register a moving image to a fixed image",
                       description="Rigid 2D registration (tx, ty, angle) of MOVING to FIXED by an entropic measure "
                                   "(Jensen-Tsallis by default, thesis ch. 2) with coarse-to-fine SPSA. Prints the "
                                   "transform in ITK's convention: T(x) = R(angle)(x - c) + c + t, x = (column, row) "
                                   "pixels, c = ((W-1)/2, (H-1)/2) of FIXED, moving(T(x)) ~ fixed(x).")
    p.add_argument("fixed", help="fixed (reference) image: PNG, TIFF, NIfTI, DICOM, MetaImage")
    p.add_argument("moving", help="moving (target) image")
    p.add_argument("--metric", default="jt", choices=["jt", "jr", "mi", "tmi"],
                   help="jt Jensen-Tsallis (default), jr Jensen-Renyi, mi mutual information, tmi Tsallis MI")
    p.add_argument("--alpha", type=float, default=2.0, help="entropy order of jt, jr, tmi (default 2, the thesis's)")
    p.add_argument("--weights", default="histogram", choices=["histogram", "uniform"],
                   help="Jensen weights (default: the reference histogram, the thesis's)")
    p.add_argument("--optimizer", default="spsa", choices=["spsa", "powell"], help="SPSA (default) or Powell")
    p.add_argument("--seed", type=int, default=0, help="seed of SPSA (default 0; the same seed gives the same result)")
    p.add_argument("--fixed-slice", type=int, help="slice of the fixed image if it is a 3D volume")
    p.add_argument("--moving-slice", type=int, help="slice of the moving image if it is a 3D volume")
    p.add_argument("--out", metavar="DIR", help="write moving_resampled.png/.tif, overlay.png and registration.json")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(handler=cmd_register)


def cmd_register(args: argparse.Namespace) -> int:
    from topomatch.pipeline.config import build_experiment
    from topomatch.pipeline.item import run_item

    fixed, moving = Path(args.fixed), Path(args.moving)
    for path in (fixed, moving):
        if not path.exists():
            raise InputError(path, "file not found")
    experiment = build_experiment(register_config(fixed.resolve(), moving.resolve(), args))
    (item,) = experiment.items()
    result = run_item(item, None)
    if not result.ok:
        if result.error_stage == "load_pair" or "cannot read" in (result.error or ""):
            raise InputError(None, result.error or "cannot read the images")
        raise StageError(result.error or "registration failed")
    reg = result.final("registration")
    t = reg.transform
    summary = {
        "fixed": str(fixed),
        "moving": str(moving),
        "convention": "ITK: T(x) = R(angle)(x - c) + c + t, x = (col, row) px, moving(T(x)) ~ fixed(x)",
        "tx": round(t.tx, 6), "ty": round(t.ty, 6), "angle": round(t.angle, 6),
        "center": [round(c, 3) for c in t.center],
        "metric": args.metric, "alpha": args.alpha, "method": reg.method,
        "objective": reg.value, "iterations": reg.iterations, "evaluations": reg.evaluations,
        "seconds": round(reg.seconds, 4), "ok": reg.ok, "reason": reg.reason,
    }
    if args.out:
        summary["files"] = write_outputs(Path(args.out), result, summary)
    if args.json:
        print(json.dumps(summary))
    else:
        for key in ("tx", "ty", "angle", "objective", "iterations", "seconds", "ok", "reason", "method", "center",
                    "files"):
            if key in summary and (key != "reason" or summary[key]):
                print(f"{key:>10}: {summary[key]}")
    if not reg.ok:
        raise RegistrationFlagged(f"registration flagged: {reg.reason}")
    return 0


def _to_uint8(data, reference):
    import numpy as np

    lo, hi = float(reference.min()), float(reference.max())
    if lo >= 0 and hi <= 255 and np.allclose(reference, np.round(reference)):
        return np.clip(np.round(data), 0, 255).astype(np.uint8)
    return np.clip(np.round((data - lo) / (hi - lo) * 255), 0, 255).astype(np.uint8)


def write_outputs(out: Path, result, summary: dict) -> list[str]:
    """The resampled moving image, an overlay figure and the summary with history, in ``out``."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from PIL import Image as PILImage

    from topomatch.pipeline.cache import atomic_write_bytes, atomic_write_text
    from topomatch.pipeline.registration_reports import overlay_figure
    from topomatch.stages.registration.interpolation import resample

    out.mkdir(parents=True, exist_ok=True)
    fixed, moving, reg = result.final("fixed"), result.final("moving"), result.final("registration")
    resampled = resample(moving, reg.transform, fixed.shape)
    paths = [out / "moving_resampled.png", out / "moving_resampled.tif", out / "overlay.png", out / "registration.json"]
    buf = io.BytesIO()
    PILImage.fromarray(_to_uint8(resampled, moving.data)).save(buf, format="PNG")
    atomic_write_bytes(paths[0], buf.getvalue())
    buf = io.BytesIO()
    PILImage.fromarray(resampled.astype(np.float32)).save(buf, format="TIFF")
    atomic_write_bytes(paths[1], buf.getvalue())
    fig = overlay_figure(fixed, moving, reg, title=f"{Path(summary['fixed']).name} <- {Path(summary['moving']).name}")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(paths[2], buf.getvalue())
    history = {k: np.asarray(v).tolist() for k, v in reg.history.items()}
    atomic_write_text(paths[3], json.dumps({**summary, "history": history}, default=str))
    return [str(p) for p in paths]


if __name__ == "__main__":  # pragma: no cover
    from topomatch.pipeline.cli import main

    sys.exit(main())
