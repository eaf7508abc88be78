"""Speed, accuracy and memory of the Fiedler pair (thesis ch. 4) against the libigl reference path.

Usage::

    .venv/bin/python benchmarks/spectral_skeleton.py [MESH] [--k 3] [--repeat 7] [--alternatives] [--json OUT]

MESH defaults to ``$TOPOMATCH_DATA_ROOT/meshes/classic/horse_cyberware.ply`` (48,485 vertices).
Loading is excluded from every timing. Measured in the same process, interleaved, ``--repeat``
times each, medians reported:

- **ours**: ``stages.spectral.laplacian.laplacian`` (vectorised assembly + validation, connected
  components included) + ``topomatch.stages.spectral.eigen.smallest_eigenpairs(Q, K, k)``
  (``method='auto'``, i.e. sparse LDL^T of ``Q - sigma K`` + block Krylov; the constant counts in k);
- **reference**: ``igl.cotmatrix`` + ``igl.massmatrix(FULL)`` + ``igl.spectra.eigs(-L, M, k,
  EIGS_TYPE_SM)``, the path DESIGN.md names as the reference.

Accuracy: lambda2 of both, and of an independent accurate solve (``scipy.sparse.linalg.eigsh``
in shift-invert mode, its own SuperLU factorisation, ARPACK tolerance 0), with the relative
residual ``||Q x - lambda K x|| / ||Q x||`` of each Fiedler vector.

On a shared machine the minima are the better estimate of the cost (other processes only
add time); both are reported, with the 1-minute load average.

Memory: each path is run once more in a forked child process; the peak resident set
(``ru_maxrss``) minus the child's resident set before the run is reported, together with the
tracemalloc peak of numpy/Python allocations (which misses the C++ heaps of qdldl and libigl).

``--alternatives`` also times the other solvers (median of 3) for docs/spectral.md: our
LOBPCG + AMG, multilevel, ARPACK on our factorisation, the SuperLU backend, plain scipy eigsh,
libigl's eigs with an explicit shift, libigl's assembly alone.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from topomatch.stages.mesh.io import read_mesh  # noqa: E402
from topomatch.stages.spectral.eigen import smallest_eigenpairs  # noqa: E402
from topomatch.stages.spectral.laplacian import laplacian  # noqa: E402


def default_mesh() -> Path:
    root = os.environ.get("TOPOMATCH_DATA_ROOT")
    if not root:
        sys.exit("no mesh given and TOPOMATCH_DATA_ROOT is not set (e.g. export TOPOMATCH_DATA_ROOT=../shared/data)")
    return Path(root) / "meshes" / "classic" / "horse_cyberware.ply"


def ours(mesh, k, **kw):
    lap = laplacian(mesh)
    e = smallest_eigenpairs(lap.Q, lap.K, k, V=mesh.V, F=mesh.F, **kw)
    return e.values, e.vectors, e


def reference(mesh, k):
    import igl
    import igl.spectra

    L = igl.cotmatrix(mesh.V, mesh.F)
    M = igl.massmatrix(mesh.V, mesh.F, igl.MASSMATRIX_TYPE_FULL)
    U, S = igl.spectra.eigs((-L).tocsc(), M.tocsc(), k, igl.spectra.EIGS_TYPE_SM)
    order = np.argsort(S)
    return S[order], U[:, order]


def accurate(Q, K, k):
    import scipy.sparse.linalg as sla

    w, X = sla.eigsh(Q.tocsc(), k=k, M=K.tocsc(), sigma=-1e-6, which="LM", tol=0)
    order = np.argsort(w)
    return w[order], X[:, order]


def rel_residual(Q, K, lam, x):
    r = Q @ x - lam * (K @ x)
    return float(np.linalg.norm(r) / np.linalg.norm(Q @ x))


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return time.perf_counter() - t, out


def peak_memory(fn) -> dict:
    """Run ``fn`` in a forked child: (maxrss - rss before) in MiB and the tracemalloc peak in MiB."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        os.close(r)
        with open("/proc/self/statm") as fh:
            rss_before = int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
        maxrss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        tracemalloc.start()
        fn()
        _, traced = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        base = max(rss_before, maxrss_before) if maxrss > maxrss_before else rss_before
        out = {"rss_peak_delta_mib": (maxrss - base) / 2**20, "tracemalloc_peak_mib": traced / 2**20}
        os.write(w, json.dumps(out).encode())
        os._exit(0)
    os.close(w)
    data = b""
    while chunk := os.read(r, 4096):
        data += chunk
    os.waitpid(pid, 0)
    return json.loads(data)


def alternatives(mesh, k, Q, K) -> dict:
    import igl
    import igl.spectra
    import scipy.sparse.linalg as sla

    rows = {}

    def add(name, fn, reps=3):
        times, lam2 = [], None
        for _ in range(reps):
            t, out = timed(fn)
            times.append(t)
            lam2 = out
        rows[name] = {"seconds": statistics.median(times), "lambda2": float(lam2)}

    add("ours auto (LDL^T + block Krylov)", lambda: ours(mesh, k)[0][1])
    add("ours auto with threads=2 (BLAS + 2 solve threads)", lambda: ours(mesh, k, threads=2)[0][1])
    add("ours shift_invert, SuperLU backend", lambda: ours(mesh, k, method="shift_invert", backend="superlu")[0][1])
    add("ours ARPACK on our LDL^T", lambda: ours(mesh, k, method="shift_invert", maxiter=1, fallback=False)[0][1])
    add("ours lobpcg (LOBPCG + pyamg SA)", lambda: ours(mesh, k, method="lobpcg", fallback=False)[0][1], reps=1)
    add("ours multilevel (decimate 3000 + LOBPCG/AMG)",
        lambda: ours(mesh, k, method="multilevel", fallback=False)[0][1], reps=1)
    add("ours laplacian() alone", lambda: laplacian(mesh).area * 0)
    add("igl cotmatrix + massmatrix alone",
        lambda: igl.massmatrix(mesh.V, mesh.F, igl.MASSMATRIX_TYPE_FULL).sum() * 0 + igl.cotmatrix(mesh.V, mesh.F).sum() * 0)

    def scipy_eigsh():
        lap = laplacian(mesh)
        w = sla.eigsh(lap.Q.tocsc(), k=k, M=lap.K.tocsc(), sigma=-1e-3, which="LM")[0]
        return np.sort(w)[1]

    add("scipy eigsh shift-invert (SuperLU, default tol)", scipy_eigsh)

    def igl_sigma():
        L = igl.cotmatrix(mesh.V, mesh.F)
        M = igl.massmatrix(mesh.V, mesh.F, igl.MASSMATRIX_TYPE_FULL)
        sigma = -1e-3
        S = np.sort(igl.spectra.eigs((-L).tocsc(), M.tocsc(), k, sigma)[1])
        return S[1] - 2 * sigma  # libigl 2.6.3 returns lambda + 2 sigma (measured)

    add("igl eigs with sigma = -1e-3 (value + 2 sigma corrected)", igl_sigma)
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mesh", nargs="?", help="mesh file (default: the horse of $TOPOMATCH_DATA_ROOT)")
    p.add_argument("--k", type=int, default=3, help="eigenpairs, constant included (default 3)")
    p.add_argument("--repeat", type=int, default=7, help="timed runs of each path (default 7)")
    p.add_argument("--alternatives", action="store_true", help="also time the other solvers")
    p.add_argument("--json", help="also write the JSON summary to this file")
    args = p.parse_args(argv)

    path = Path(args.mesh) if args.mesh else default_mesh()
    mesh, _ = read_mesh(path)
    k = args.k

    ours(mesh, k)  # warm-up (imports, first-touch allocations)
    reference(mesh, k)
    t_ours, t_ref = [], []
    for _ in range(args.repeat):
        t, (w_ours, X_ours, e) = timed(lambda: ours(mesh, k))
        t_ours.append(t)
        t, (w_ref, X_ref) = timed(lambda: reference(mesh, k))
        t_ref.append(t)

    lap = laplacian(mesh)
    Q, K = lap.Q, lap.K
    w_acc, X_acc = accurate(Q, K, k)
    s_ours, s_ref = statistics.median(t_ours), statistics.median(t_ref)
    mem_ours = peak_memory(lambda: ours(mesh, k))
    mem_ref = peak_memory(lambda: reference(mesh, k))
    summary = {
        "mesh": path.name,
        "vertices": mesh.n_vertices,
        "faces": mesh.n_faces,
        "k": k,
        "repeat": args.repeat,
        "seconds_ours": s_ours,
        "seconds_reference": s_ref,
        "speedup": s_ref / s_ours,
        "seconds_ours_min": min(t_ours),
        "seconds_reference_min": min(t_ref),
        "speedup_of_minima": min(t_ref) / min(t_ours),
        "loadavg_1min_after": os.getloadavg()[0],
        "seconds_ours_all": t_ours,
        "seconds_reference_all": t_ref,
        "method": e.method,
        "n_solves": e.n_solves,
        "lambda2_ours": float(w_ours[1]),
        "lambda2_reference": float(w_ref[1]),
        "lambda2_accurate": float(w_acc[1]),
        "rel_diff_ours_vs_reference": float(abs(w_ours[1] - w_ref[1]) / w_ref[1]),
        "rel_diff_ours_vs_accurate": float(abs(w_ours[1] - w_acc[1]) / w_acc[1]),
        "rel_diff_reference_vs_accurate": float(abs(w_ref[1] - w_acc[1]) / w_acc[1]),
        "residual_ours": rel_residual(Q, K, w_ours[1], X_ours[:, 1]),
        "residual_reference": rel_residual(Q, K, w_ref[1], X_ref[:, 1]),
        "residual_accurate": rel_residual(Q, K, w_acc[1], X_acc[:, 1]),
        "lambda_ours": [float(x) for x in w_ours],
        "lambda_reference": [float(x) for x in w_ref],
        "lambda_accurate": [float(x) for x in w_acc],
        "memory_ours": mem_ours,
        "memory_reference": mem_ref,
        "machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "platform": platform.platform()},
    }
    if args.alternatives:
        summary["alternatives"] = alternatives(mesh, k, Q, K)

    print(json.dumps(summary, indent=2))
    print()
    print(f"| {path.name}, n = {mesh.n_vertices}, k = {k} | ours | libigl reference |")
    print("|---|---|---|")
    print(f"| seconds (median of {args.repeat}) | {s_ours:.3f} | {s_ref:.3f} |")
    print(f"| speedup | {s_ref / s_ours:.2f}x | 1 |")
    print(f"| seconds (minimum) | {min(t_ours):.3f} | {min(t_ref):.3f} |")
    print(f"| speedup of the minima | {min(t_ref) / min(t_ours):.2f}x | 1 |")
    print(f"| lambda2 | {w_ours[1]:.10g} | {w_ref[1]:.10g} |")
    print(f"| rel. diff. to accurate lambda2 = {w_acc[1]:.10g} | {summary['rel_diff_ours_vs_accurate']:.1e} | "
          f"{summary['rel_diff_reference_vs_accurate']:.1e} |")
    print(f"| rel. residual of phi2 | {summary['residual_ours']:.1e} | {summary['residual_reference']:.1e} |")
    print(f"| peak RSS increase (MiB) | {mem_ours['rss_peak_delta_mib']:.0f} | {mem_ref['rss_peak_delta_mib']:.0f} |")
    print(f"| tracemalloc peak (MiB) | {mem_ours['tracemalloc_peak_mib']:.0f} | {mem_ref['tracemalloc_peak_mib']:.0f} |")
    if args.alternatives:
        print()
        print("| solver | seconds | lambda2 |")
        print("|---|---|---|")
        for name, row in summary["alternatives"].items():
            print(f"| {name} | {row['seconds']:.3f} | {row['lambda2']:.10g} |")
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
