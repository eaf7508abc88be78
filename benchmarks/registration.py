"""Accuracy, speed and determinism of the registration (thesis ch. 2) against SimpleITK, in one run.

Usage::

    .venv/bin/python benchmarks/registration.py [--cases 60] [--seeds 5] [--json benchmarks/results/registration.json]

What it measures (everything in one process, one case after the other, so that the time ratios
compare like with like on this machine):

1. **ITK cases** (bundled ``registration_pairs.csv``, scored against the ``consensus_*`` columns,
   about ((W-1)/2, (H-1)/2)): mean TRE of Jensen-Tsallis + SPSA for ``--seeds`` seeds (max over
   seeds), of Powell on the same objective, and of SimpleITK's Mattes MI with two optimisers
   (conjugate gradient with line search; regular-step gradient descent).
2. **Accuracy sweep**: ``--cases`` random misalignments (|tx|, |ty| <= 20 px, |angle| <= 25 deg,
   seed 2024) of PD -> PD and T1 (fixed) vs PD (moved), 181 x 217 pixels: success rate (mean TRE
   <= 1 px), median TRE and seconds per case for JT, JR, MI and Tsallis MI with SPSA, and both
   SimpleITK set-ups; how many failures the self-check flagged.
3. **Speed ratio**: median seconds of JT + SPSA divided by the median seconds of each SimpleITK
   set-up on the same sweep cases (SimpleITK uses its default thread count).
4. **Determinism**: the same seed twice gives bit-identical parameters.
5. **Ablation** on the thesis's three misalignments of the PD slice: plain single-resolution SPSA
   on a 64-bin JT objective (Spall gains, no normalisation, 3000 iterations) vs the default.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from topomatch.stages.registration.evaluate import evaluate_registration
from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.misalign import MisalignParams, moved
from topomatch.stages.registration.params import RegisterParams
from topomatch.stages.registration.register import register
from topomatch.stages.registration.simpleitk_reference import SimpleITKParams, sitk_register
from topomatch.stages.registration.transform import RigidTransform

REPO = Path(__file__).resolve().parents[1]
ITK = REPO / "data" / "images" / "itk"

SITK = {
    "simpleitk line search": SimpleITKParams(optimizer="line_search", learning_rate=1.0, iterations=100),
    "simpleitk regular step": SimpleITKParams(optimizer="regular_step", learning_rate=2.0, iterations=300),
}


def ours(metric: str = "jt", **kw) -> RegisterParams:
    return RegisterParams(metric=metric, **kw)


def itk_cases(seeds: int) -> list[dict]:
    rows = []
    with open(ITK / "registration_pairs.csv", newline="") as fh:
        cases = list(csv.DictReader(fh))
    for r in cases:
        if not r["consensus_tx"]:
            continue
        fixed, moving = read_image(ITK / r["fixed"]), read_image(ITK / r["moving"])
        truth = {"tx": float(r["consensus_tx"]), "ty": float(r["consensus_ty"]),
                 "angle": float(r["consensus_rotation_deg"])}
        case = f"{r['fixed'].removesuffix('.png')} <- {r['moving'].removesuffix('.png')}"
        runs = {}
        jt = [register(fixed, moving, ours(seed=s)) for s in range(seeds)]
        runs["jt spsa"] = jt
        runs["jt powell"] = [register(fixed, moving, ours(optimizer="powell"))]
        for name, p in SITK.items():
            runs[name] = [sitk_register(fixed, moving, p)]
        for name, regs in runs.items():
            evs = [evaluate_registration(fixed, g, truth) for g in regs]
            rows.append({"case": case, "method": name, "runs": len(regs),
                         "max_tre": max(e.tre_mean for e in evs), "median_tre": statistics.median(e.tre_mean for e in evs),
                         "tx": regs[0].transform.tx, "ty": regs[0].transform.ty, "angle": regs[0].transform.angle,
                         "median_seconds": statistics.median(g.seconds for g in regs), "flagged": sum(not g.ok for g in regs)})
    return rows


def sweep(n: int) -> tuple[list[dict], dict[str, list[float]]]:
    pd_, t1 = read_image(ITK / "BrainProtonDensitySlice.png"), read_image(ITK / "BrainT1Slice.png")
    methods = {"jt spsa": ours("jt"), "jr spsa": ours("jr"), "mi spsa": ours("mi"), "tmi spsa": ours("tmi"), **SITK}
    results: dict[tuple[str, str], list] = {}
    for pair, fixed in (("PD-PD", pd_), ("T1-PD", t1)):
        for i in range(n):
            T = MisalignParams(index=i, seed=2024, max_translation=20, max_angle=25).transform(pd_.center)
            moving = moved(pd_, T)
            truth = {"tx": T.tx, "ty": T.ty, "angle": T.angle}
            for name, p in methods.items():  # interleaved: every method sees the same machine load
                reg = sitk_register(fixed, moving, p) if name.startswith("simpleitk") else register(fixed, moving, p)
                ev = evaluate_registration(fixed, reg, truth)
                results.setdefault((pair, name), []).append(ev)
    rows, seconds = [], {}
    for pair in ("PD-PD", "T1-PD", "all"):
        for name in methods:
            evs = [e for (p, m), v in results.items() for e in v if m == name and (pair == "all" or p == pair)]
            tre = np.array([e.tre_mean for e in evs])
            secs = [e.seconds for e in evs]
            ok = tre <= 1.0
            flagged = np.array([e.flagged for e in evs])
            rows.append({"pairs": pair, "method": name, "cases": len(evs), "success_rate": float(ok.mean()),
                         "median_tre": float(np.median(tre)), "median_seconds": statistics.median(secs),
                         "mean_seconds": float(np.mean(secs)), "failed": int((~ok).sum()),
                         "failed_flagged": int((~ok & flagged).sum()), "ok_but_flagged": int((ok & flagged).sum())})
            if pair == "all":
                seconds[name] = secs
    return rows, seconds


def determinism() -> dict:
    pd_ = read_image(ITK / "BrainProtonDensitySlice.png")
    moving = moved(pd_, RigidTransform.euler2d(10, 20, 20, pd_.center))
    a = register(pd_, moving, ours(seed=7)).transform.parameters
    b = register(pd_, moving, ours(seed=7)).transform.parameters
    c = register(pd_, moving, ours(seed=8)).transform.parameters
    return {"same_seed_identical": a == b, "other_seed_differs": a != c, "params_seed7": list(a),
            "params_seed8": list(c)}


def ablation() -> list[dict]:
    pd_ = read_image(ITK / "BrainProtonDensitySlice.png")
    plain = RegisterParams(schedule=[{"spacing": 0.0, "bins": 64, "iterations": 3000, "step": 1.0, "c": 1.0,
                                      "interpolation": "linear"}],
                           optimizer={"normalize": False, "newton": 0.0}, check={"search": False, "retry": False})
    variants = {"plain SPSA, 1 level, 64 bins, 3000 it.": plain, "default": RegisterParams()}
    rows = []
    for theta in ((5, 5, 5), (5, 10, 15), (10, 20, 20)):
        moving = moved(pd_, RigidTransform.euler2d(*theta, pd_.center))
        for name, p in variants.items():
            reg = register(pd_, moving, p)
            ev = evaluate_registration(pd_, reg, dict(zip(("tx", "ty", "angle"), theta)))
            rows.append({"theta": list(theta), "variant": name, "tre_mean": ev.tre_mean, "seconds": reg.seconds,
                         "evaluations": reg.evaluations})
    return rows


def table(rows: list[dict], columns: list[str]) -> str:
    def fmt(v):
        return f"{v:.4g}" if isinstance(v, float) else str(v)

    out = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    out += ["| " + " | ".join(fmt(r.get(c, "")) for c in columns) + " |" for r in rows]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=60, help="random misalignments per pair (default 60)")
    ap.add_argument("--seeds", type=int, default=5, help="SPSA seeds on the ITK cases (default 5)")
    ap.add_argument("--skip-ablation", action="store_true")
    ap.add_argument("--json", help="write all results to this JSON file")
    args = ap.parse_args()
    t0 = time.perf_counter()
    out: dict = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                             "load_average_at_start": os.getloadavg()}}
    out["itk_cases"] = itk_cases(args.seeds)
    print("## ITK cases (mean TRE in px against the consensus columns)\n")
    print(table(out["itk_cases"], ["case", "method", "runs", "max_tre", "median_tre",
                                   "tx", "ty", "angle", "median_seconds", "flagged"]))
    rows, seconds = sweep(args.cases)
    out["sweep"] = rows
    print(f"\n## Accuracy sweep ({args.cases} random misalignments per pair, success = mean TRE <= 1 px)\n")
    print(table(rows, ["pairs", "method", "cases", "success_rate", "median_tre", "median_seconds", "mean_seconds",
                       "failed", "failed_flagged", "ok_but_flagged"]))
    ratios = {name: statistics.median(seconds["jt spsa"]) / statistics.median(s)
              for name, s in seconds.items() if name.startswith("simpleitk")}
    out["speed_ratio_jt_over_simpleitk"] = ratios
    print("\n## Speed: median seconds of JT + SPSA / median seconds of SimpleITK (same cases, same run)\n")
    for name, r in ratios.items():
        print(f"- {name}: {r:.3f}")
    out["determinism"] = determinism()
    print(f"\n## Determinism\n\n{out['determinism']}")
    if not args.skip_ablation:
        out["ablation"] = ablation()
        print("\n## Ablation (PD slice, thesis misalignments)\n")
        print(table(out["ablation"], ["theta", "variant", "tre_mean", "seconds", "evaluations"]))
    out["machine"]["load_average_at_end"] = os.getloadavg()
    out["seconds_total"] = time.perf_counter() - t0
    print(f"\nload average at start {out['machine']['load_average_at_start']}, at end {out['machine']['load_average_at_end']}; "
          f"total {out['seconds_total']:.0f} s")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1, default=str))


if __name__ == "__main__":
    main()
