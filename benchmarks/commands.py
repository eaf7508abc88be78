"""The commands as a user runs them, end to end, against a reference measured in the same run.

Usage::

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/commands.py [--repeat 5] [--json OUT]

Each measurement runs the installed ``topomatch`` command in a fresh process (the way a user
meets it: interpreter start, imports, work, output), ``--repeat`` times, interleaved with its
reference; medians and minima are reported (on a shared machine the minima are the better
estimate: other processes only add time).

- ``topomatch --help``: wall time of the process, against a bare ``python -c pass``.
- ``topomatch register`` of the bundled ITK pair (Border20 <- Shifted13x17y): wall time of the
  process, against SimpleITK's own Mattes registration of the same pair measured in this process
  (:func:`topomatch.stages.registration.simpleitk_reference.sitk_register` with regular-step
  gradient descent, learning rate 2, 300 iterations, 3-level pyramid; images in memory).
- ``topomatch skeleton horse --function fiedler --json``: the command's stage seconds from
  ``clean`` to ``prune`` (load excluded), against the libigl reference path in this process
  (``igl.cotmatrix`` + ``igl.massmatrix(FULL)`` + ``igl.spectra.eigs(-L, M, 2, SM)``), with
  lambda2 of both against scipy's ``eigsh`` in shift-invert mode on the same L, M.
- ``topomatch skeleton big.ply --function mixture --json`` on large meshes made from the horse
  (``--large``): its stage seconds from ``clean`` to ``prune`` against one ``igl.cotmatrix`` of the
  same mesh in this process. Two meshes: the horse midpoint-subdivided twice (1.55 M faces, needs
  no repair) and the same decimated to 1.3 M faces by fast-simplification (which leaves ~12,000
  coincident vertices, so ``clean`` merges them and drops ~24,000 degenerate faces).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ITK = REPO / "data" / "images" / "itk"
TOPOMATCH = [sys.executable, "-m", "topomatch"]


#: The environment of the measured commands: a user's, whose Python writes and then reuses the bytecode
#: of the project's modules. (A sandbox that sets PYTHONDONTWRITEBYTECODE=1 makes every command compile
#: them again: +0.35 s for ``register`` on 2026-12-02.) Each command also runs once, untimed, first, but
#: the large skeletons (10 s each): their first run compiles the mixture modules, and minima are reported.
USER_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def process_seconds(cmd: list[str]) -> tuple[float, str]:
    t = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=USER_ENV)
    return time.perf_counter() - t, out.stdout


def in_process_seconds(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def summary(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values)}


def help_rows(repeat: int) -> dict:
    ours, ref = [], []
    process_seconds(TOPOMATCH + ["--help"])  # warm-up: bytecode caches written
    for _ in range(repeat):
        ours.append(process_seconds(TOPOMATCH + ["--help"])[0])
        ref.append(process_seconds([sys.executable, "-c", "pass"])[0])
    return {"topomatch --help (process)": summary(ours), "python -c pass (process, reference)": summary(ref)}


def register_rows(repeat: int) -> dict:
    from topomatch.stages.registration.io import read_image
    from topomatch.stages.registration.simpleitk_reference import SimpleITKParams, sitk_register

    # SimpleITK's usual 2D set-up: Mattes MI, regular-step gradient descent, 3-level pyramid
    sitk_params = SimpleITKParams(optimizer="regular_step", learning_rate=2.0, iterations=300)

    fixed_path, moving_path = ITK / "BrainProtonDensitySliceBorder20.png", ITK / "BrainProtonDensitySliceShifted13x17y.png"
    fixed, moving = read_image(fixed_path), read_image(moving_path)
    sitk_register(fixed, moving, sitk_params)  # warm-up: SimpleITK's own start-up is not part of its time
    command = TOPOMATCH + ["register", str(fixed_path), str(moving_path), "--json"]
    process_seconds(command)  # warm-up: bytecode caches written
    ours, inner, ref = [], [], []
    for _ in range(repeat):
        t, out = process_seconds(command)
        ours.append(t)
        inner.append(json.loads(out)["seconds"])
        ref.append(in_process_seconds(lambda: sitk_register(fixed, moving, sitk_params)))
    return {"topomatch register (process)": summary(ours), "  of which the registration": summary(inner),
            "SimpleITK Mattes, in process (reference)": summary(ref)}


def skeleton_rows(repeat: int, mesh_path: Path) -> dict:
    import igl
    import igl.spectra
    import scipy.sparse.linalg as sla

    from topomatch.meshes import read_mesh
    from topomatch.stages.spectral.laplacian import laplacian

    mesh = read_mesh(mesh_path)

    def reference():
        L = igl.cotmatrix(mesh.V, mesh.F)
        M = igl.massmatrix(mesh.V, mesh.F, igl.MASSMATRIX_TYPE_FULL)
        U, S = igl.spectra.eigs((-L).tocsc(), M.tocsc(), 2, igl.spectra.EIGS_TYPE_SM)
        return float(np.sort(S)[1])

    command = TOPOMATCH + ["skeleton", str(mesh_path), "--function", "fiedler", "--json"]
    process_seconds(command)  # warm-up: bytecode caches written
    ours, stage_sums, ref, lam_ref = [], [], [], None
    for _ in range(repeat):
        t, out = process_seconds(command)
        result = json.loads(out)
        ours.append(t)
        stage_sums.append(sum(v for k, v in result["seconds"].items() if k != "load"))
        t0 = time.perf_counter()
        lam_ref = reference()
        ref.append(time.perf_counter() - t0)
    lap = laplacian(mesh)
    w = sla.eigsh(lap.Q.tocsc(), k=3, M=lap.K.tocsc(), sigma=-1e-6, which="LM", tol=0)[0]
    exact = float(np.sort(w)[1])
    return {"topomatch skeleton (process)": summary(ours), "  stages clean..prune": summary(stage_sums),
            "libigl reference path, in process": summary(ref),
            "lambda2": {"topomatch": result["lambda2"], "libigl eigs": lam_ref, "scipy eigsh (exact)": exact,
                        "topomatch rel. error": abs(result["lambda2"] - exact) / exact,
                        "libigl rel. error": abs(lam_ref - exact) / exact},
            "endpoints": result["n_endpoints"]}


def large_skeleton_rows(repeat: int, mesh_path: Path, folder: Path) -> dict:
    import igl

    from topomatch.meshes import read_mesh
    from topomatch.stages.mesh.decimate import simplify_to_target

    horse = read_mesh(mesh_path)
    V, F = igl.upsample(horse.V, horse.F, number_of_subdivs=2)
    Vd, Fd, _ = simplify_to_target(V, F, 1_300_000)
    out = {}
    for name, (Vm, Fm) in {"subdivided (no repair)": (V, F), "decimated (needs repair)": (Vd, Fd)}.items():
        path = folder / f"large_{len(Fm)}.ply"
        igl.write_triangle_mesh(str(path), Vm, Fm)
        stages, ref, seconds = [], [], {}
        for _ in range(repeat):
            _, text = process_seconds(TOPOMATCH + ["skeleton", str(path), "--function", "mixture", "--json", "-q"])
            seconds = json.loads(text)["seconds"]
            stages.append(sum(v for k, v in seconds.items() if k != "load"))
            ref.append(in_process_seconds(lambda: igl.cotmatrix(Vm, Fm)))
        out[name] = {"faces": int(len(Fm)), "stages clean..prune": summary(stages),
                     "igl.cotmatrix, in process (reference)": summary(ref), "last run's stages": seconds}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--mesh", help="skeleton mesh (default: the horse of the data root)")
    parser.add_argument("--large", action="store_true", help="also the mixture skeleton of 1.3-1.55 M-face meshes")
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args()
    rows = {"help": help_rows(args.repeat), "register": register_rows(args.repeat)}
    mesh = Path(args.mesh) if args.mesh else None
    if mesh is None and os.environ.get("TOPOMATCH_DATA_ROOT"):
        mesh = Path(os.environ["TOPOMATCH_DATA_ROOT"]) / "meshes" / "classic" / "horse_cyberware.ply"
    if mesh is not None:
        rows["skeleton"] = skeleton_rows(args.repeat, mesh)
        if args.large:
            import tempfile

            with tempfile.TemporaryDirectory() as folder:
                rows["large skeleton"] = large_skeleton_rows(args.repeat, mesh, Path(folder))
    rows["load_average"] = os.getloadavg()[0]
    print(json.dumps(rows, indent=1))
    h, r = rows["help"], rows["register"]
    print(f"\n--help: {h['topomatch --help (process)']['min']:.3f} s (bare python "
          f"{h['python -c pass (process, reference)']['min']:.3f} s)")
    print(f"register: {r['topomatch register (process)']['min']:.3f} s = "
          f"{r['topomatch register (process)']['min'] / r['SimpleITK Mattes, in process (reference)']['min']:.2f}x "
          f"SimpleITK in process ({r['SimpleITK Mattes, in process (reference)']['min']:.3f} s)")
    if "skeleton" in rows:
        s = rows["skeleton"]
        ratio = s["libigl reference path, in process"]["min"] / s["  stages clean..prune"]["min"]
        print(f"skeleton: stages clean..prune {s['  stages clean..prune']['min']:.3f} s, reference "
              f"{s['libigl reference path, in process']['min']:.3f} s: {ratio:.2f}x faster; lambda2 rel. error "
              f"{s['lambda2']['topomatch rel. error']:.1e} (libigl's {s['lambda2']['libigl rel. error']:.1e})")
    for name, r in rows.get("large skeleton", {}).items():
        ours, ref = r["stages clean..prune"]["min"], r["igl.cotmatrix, in process (reference)"]["min"]
        print(f"mixture skeleton, {name}, {r['faces']:,} faces: stages clean..prune {ours:.3f} s = "
              f"{ours / ref:.2f}x one igl.cotmatrix ({ref:.3f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
