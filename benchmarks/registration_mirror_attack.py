"""An attack with a moving image that **no rigid transform can align: the corpus's moving image mirrored** along one
array axis (a flip from a convention mismatch: a PNG and a NIfTI, radiological and neurological order, a DICOM
series read in reverse), registered as a user does (files, ``topomatch.register``, defaults).

A hostile user's pass (tenth session) found a mid-sagittal ITK slice mirrored front to back registered with ``ok``.
Here every case of the given report splits (seen: nothing is chosen on them) is registered once per array axis with
its moving image flipped along it, about the grid's centre, geometry kept. Every answer is wrong by construction; a
pass is silent unless the anatomy is symmetric about that axis (a brain's left-right axis: the flipped image is then
nearly the same image, and no intensity measure can tell). Rows: case, source, kind, axis, ok, flags, and the flipped
axis's physical x component (``x_component``: 1 for a left-right axis, 0 across it; oblique grids between). Run::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_mirror_attack.py --splits final44,final45 \\
        --dims 2,3 --json benchmarks/results/registration_mirror_attack.json
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import registration_corpus as rc  # noqa: E402


def mirrored_case(case: rc.Case, axis: int) -> rc.Case:
    """The case with its moving image flipped along array ``axis`` (its geometry kept)."""
    data = np.ascontiguousarray(np.flip(case.moving.data, axis=axis))
    return rc.Case(case.spec, case.fixed, case.moving.with_data(data), case.truth)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--splits", default="final44,final45")
    ap.add_argument("--dims", default="2,3")
    ap.add_argument("--metric", default="jt")
    ap.add_argument("--cases-scale", type=float, default=1.0, help="scales every split's case count (as the corpus's)")
    ap.add_argument("--kinds-attack", action="store_true", help="the kind attack's splits and kinds (kinds-11 ...)")
    ap.add_argument("--oblique-attack", action="store_true", help="the oblique attack's splits (oblique-2 ...)")
    ap.add_argument("--sources-attack", type=Path, metavar="WHEELS", help="the source attack's splits (sources: dipy's, "
                    "pydicom's and nibabel's data), the dipy and pydicom wheels in the folder WHEELS")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    if args.kinds_attack:
        import registration_kind_attack

        registration_kind_attack.register_split()
    if args.oblique_attack:
        import registration_oblique_attack

        registration_oblique_attack.register_split()
    if args.sources_attack:
        import registration_source_attack

        registration_source_attack.WHEEL_DIR.append(args.sources_attack)
        registration_source_attack.register_split()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for split in args.splits.split(","):
            for dim in (int(d) for d in args.dims.split(",")):
                for spec in rc.plan_split(split, dim, args.cases_scale):
                    case = rc.build_case(spec)
                    for axis in range(dim):
                        try:
                            fixed_path, moving_path, fixed, moving = rc.write_case(mirrored_case(case, axis), Path(tmp))
                        except Exception as exc:  # noqa: BLE001 (a draw that cannot be written: not a case)
                            print(f"{spec.id} axis {axis}: {exc}", flush=True)
                            continue
                        result = rc.run_ours(args.metric, fixed_path, moving_path, fixed, moving)
                        along = np.asarray(case.moving.direction)[:, dim - 1 - axis]  # the flipped axis, physical
                        rows.append({"case": spec.id, "split": split, "dim": dim, "source": spec.source,
                                     "kind": spec.kind, "axis": axis, "ok": result.ok, "flags": result.flags,
                                     "error": result.error, "x_component": float(abs(along[0]))})
                        print(f"{spec.id:34s} {spec.kind:20s} axis {axis} ok {result.ok!s:5} {result.flags}", flush=True)
    counts = collections.Counter((r["dim"], r["source"], r["axis"], "passed" if r["ok"] else "refused") for r in rows)
    summary = {f"{d}D {s} axis {a}": {"passed": counts[(d, s, a, "passed")], "refused": counts[(d, s, a, "refused")]}
               for d, s, a in sorted({k[:3] for k in counts})}
    for key, value in summary.items():
        print(f"{key:28s} passed {value['passed']:3d}  refused {value['refused']:3d}")
    rc.save_study(args.json, __doc__, summary, rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
