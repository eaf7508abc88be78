"""Where a 3D label map's registration time goes: the defaults, the label test alone (``check_label``: the pair's
objects registered again), and the registration without that test, at four and at one times the finest samples
(``label_samples``). In process, on the first ``--cases`` 3D pairs of ``pair-kinds-3`` (one parcellation moved by the
truth, ``registration_pair_kind_attack.py``); nothing is changed by it.

    TOPOMATCH_DATA_ROOT=../shared/data .venv/bin/python benchmarks/registration_label_time_probe.py --cases 4
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import registration_corpus as corpus  # noqa: E402
import registration_pair_kind_attack as pair_kinds  # noqa: E402

from topomatch.stages.registration import register as reg  # noqa: E402
from topomatch.stages.registration.params import RegisterParams  # noqa: E402


def seconds(fixed, moving, params: RegisterParams = RegisterParams()) -> tuple[float, float]:
    """(wall seconds of ``register``, seconds spent in its label test)."""
    spent, label = [0.0], reg.check_label

    def timed(*args):
        t = time.perf_counter()
        try:
            return label(*args)
        finally:
            spent[0] += time.perf_counter() - t

    checks, reg.CHECKS = reg.CHECKS, tuple(timed if c is label else c for c in reg.CHECKS)
    try:
        t = time.perf_counter()
        reg.register(fixed, moving, params)
        return time.perf_counter() - t, spent[0]
    finally:
        reg.CHECKS = checks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=4)
    args = ap.parse_args()
    pair_kinds.register_split()
    for spec in corpus.plan_split("pair-kinds-3", 3, 2.0)[: args.cases]:
        case = corpus.build_case(spec)
        total, label = seconds(case.fixed, case.moving)
        without, _ = seconds(case.fixed, case.moving, RegisterParams(check={"label": 0.0}))
        single, _ = seconds(case.fixed, case.moving, RegisterParams(check={"label": 0.0}, label_samples=1.0))
        print(f"{spec.id} {case.fixed.shape}: defaults {total:.2f} s (label test {label:.2f} s); without the label "
              f"test {without:.2f} s; and at 1x finest samples {single:.2f} s", flush=True)


if __name__ == "__main__":
    main()
