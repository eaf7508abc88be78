"""``topomatch register`` as a user runs it (a fresh process: interpreter, imports, reading, registration,
output), against elastix and SimpleITK on the same pairs, in the same run.

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_speed.py [--cases 20] [--json OUT]

Pairs: the report split of ``benchmarks/registration_corpus.py`` (3D: its MNI, KmeansTest and anatomical
cases; 2D: its MNI sections and ITK slices), the first ``--cases`` of each dimension, written as NIfTI files.
Per pair, interleaved so that every method meets the same machine load:

- **ours**: ``topomatch register FIXED MOVING --json`` in a new process (wall time), the defaults;
- **elastix** (3D and 2D): ``itk.elastix_registration_method`` with its default rigid map, in this process
  after a warm-up (ITK's module loading excluded: the issue's reference is elastix's in-process time);
- **ours, in process**: ``topomatch.register(fixed, moving)`` on the same in-memory images elastix is given, in this
  process after the same warm-up (imports excluded): elastix's terms, so that the process column's gap splits into
  what the registration costs and what starting a Python process that reads the files costs;
- **SimpleITK script** (2D): a new Python process that imports SimpleITK, reads both files and registers them
  (Mattes MI, regular-step gradient descent, a 3-level pyramid: the textbook set-up), wall time.

The goals (docs/registration.md): 3D, the median of ours at most elastix's in-process median; 2D, ours at most
the SimpleITK script's.

``--baseline CHECKOUT`` (another tree of the project, e.g. ``git worktree add /tmp/old REV``) adds **ours, baseline**:
the same command run from that tree's code (its compiled pass built in place, its package laid out as the editable
install lays out this one, put first on ``PYTHONPATH``), interleaved with ours on every pair, and the median of the
per-pair ratios ours / baseline: what a change did to the time a user waits, measured in one run.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402  (the corpus's cases)

SITK_SCRIPT = """
import sys, SimpleITK as sitk
f = sitk.ReadImage(sys.argv[1], sitk.sitkFloat32); m = sitk.ReadImage(sys.argv[2], sitk.sitkFloat32)
r = sitk.ImageRegistrationMethod()
r.SetMetricAsMattesMutualInformation(50); r.SetMetricSamplingStrategy(r.RANDOM); r.SetMetricSamplingPercentage(0.25, 42)
r.SetInterpolator(sitk.sitkLinear)
r.SetOptimizerAsRegularStepGradientDescent(learningRate=2.0, minStep=1e-3, numberOfIterations=300, relaxationFactor=0.5)
r.SetOptimizerScalesFromPhysicalShift(); r.SetShrinkFactorsPerLevel([4, 2, 1]); r.SetSmoothingSigmasPerLevel([2, 1, 0])
t = sitk.CenteredTransformInitializer(f, m, sitk.Euler2DTransform(), sitk.CenteredTransformInitializerFilter.MOMENTS)
r.SetInitialTransform(t, inPlace=False)
print(r.Execute(f, m).GetParameters())
"""

USER_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def process_seconds(cmd: list[str], env: dict[str, str] = USER_ENV) -> float:
    t = time.perf_counter()
    # a flagged result exits 1: still timed; run away from any checkout, whose topomatch/ folder `-m` would import
    subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tempfile.gettempdir())
    return time.perf_counter() - t


def baseline_env(checkout: Path, folder: Path) -> dict[str, str]:
    """The environment that runs ``topomatch`` from ``checkout``'s code: its compiled pass built in place, and a
    ``topomatch`` package of links to its folders (the editable install's layout) first on ``PYTHONPATH``."""
    subprocess.run([sys.executable, "setup.py", "build_ext", "--inplace"], cwd=checkout, check=True,
                   capture_output=True)
    package = folder / "baseline" / "topomatch"
    package.mkdir(parents=True)
    for item in (checkout / "topomatch").iterdir():
        (package / item.name).symlink_to(item)
    for name in ("configs", "data", "pipeline", "stages"):
        (package / name).symlink_to(checkout / name)
    return dict(USER_ENV, PYTHONPATH=str(package.parent))


def elastix_seconds(fixed, moving) -> float:
    return corpus.run_elastix(None, None, fixed, moving).seconds


def ours_seconds(fixed, moving) -> float:
    import topomatch

    t = time.perf_counter()
    topomatch.register(fixed, moving)
    return time.perf_counter() - t


def summary(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "n": len(values)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=20, help="pairs per dimension (default 20)")
    ap.add_argument("--dims", default="3,2")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--baseline", type=Path, default=None, metavar="CHECKOUT",
                    help="another tree of the project, timed beside ours (module docstring)")
    args = ap.parse_args()
    out: dict = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                             "load_average_at_start": list(os.getloadavg())}, "dims": {}}
    folder = Path(tempfile.mkdtemp(prefix="topomatch-speed-"))
    script = folder / "sitk_register.py"
    script.write_text(SITK_SCRIPT)
    ours_cmd = [sys.executable, "-m", "topomatch", "register"]
    baseline = baseline_env(args.baseline.resolve(), folder) if args.baseline else None
    for dim in (int(d) for d in args.dims.split(",")):
        specs = [s for s in corpus.plan_split("report", dim) if corpus.source_available(s.source)][: args.cases]
        pairs = [corpus.write_case(corpus.build_case(s), folder) for s in specs]
        fixed_path, moving_path, fixed, moving = pairs[0]
        corpus.run_elastix(None, None, fixed, moving)  # ITK's one-time start-up, not timed
        ours_seconds(fixed, moving)  # our imports, not timed in process (as ITK's are not)
        process_seconds(ours_cmd + [str(fixed_path), str(moving_path), "--json"])  # bytecode written once
        rows = {"ours (process)": [], "elastix (in process)": [], "ours (in process)": []}
        if dim == 2:
            rows["SimpleITK script (process)"] = []
        if baseline:
            rows["ours, baseline (process)"] = []
            process_seconds(ours_cmd + [str(fixed_path), str(moving_path), "--json"], baseline)
        for i, ((fixed_path, moving_path, fixed, moving), spec) in enumerate(zip(pairs, specs)):
            command = ours_cmd + [str(fixed_path), str(moving_path), "--json"]
            if baseline and i % 2:  # every other pair the baseline first: neither always meets a warmer machine
                rows["ours, baseline (process)"].append(process_seconds(command, baseline))
            rows["ours (process)"].append(process_seconds(command))
            if baseline and not i % 2:
                rows["ours, baseline (process)"].append(process_seconds(command, baseline))
            rows["elastix (in process)"].append(elastix_seconds(fixed, moving))
            rows["ours (in process)"].append(ours_seconds(fixed, moving))
            if dim == 2:
                rows["SimpleITK script (process)"].append(
                    process_seconds([sys.executable, str(script), str(fixed_path), str(moving_path)]))
            print(f"{dim}D {spec.id:32s} " + "  ".join(f"{k} {v[-1]:.2f} s" for k, v in rows.items()), flush=True)
        result = {k: summary(v) for k, v in rows.items()}
        reference = "elastix (in process)" if dim == 3 else "SimpleITK script (process)"
        result["ratio_ours_over_reference"] = result["ours (process)"]["median"] / result[reference]["median"]
        result["median_pair_ratio_in_process_ours_over_elastix"] = statistics.median(
            a / b for a, b in zip(rows["ours (in process)"], rows["elastix (in process)"]))
        if baseline:
            result["median_pair_ratio_ours_over_baseline"] = statistics.median(
                a / b for a, b in zip(rows["ours (process)"], rows["ours, baseline (process)"]))
            print(f"== {dim}D: ours / baseline, median over pairs {result['median_pair_ratio_ours_over_baseline']:.3f}")
        out["dims"][f"{dim}D"] = {"summary": result, "seconds": rows, "reference": reference}
        print(f"== {dim}D: median ours {result['ours (process)']['median']:.3f} s, {reference} "
              f"{result[reference]['median']:.3f} s, ratio {result['ratio_ours_over_reference']:.2f}; in process, ours / "
              f"elastix per pair {result['median_pair_ratio_in_process_ours_over_elastix']:.2f}", flush=True)
    out["machine"]["load_average_at_end"] = list(os.getloadavg())
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
