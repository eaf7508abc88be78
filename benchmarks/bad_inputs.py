"""Time and peak memory of every bad-input case (``tests/badinput/corpus.py``), as a user meets it.

Usage::

    .venv/bin/python benchmarks/bad_inputs.py [--json benchmarks/results/bad_inputs.json]

Each case runs the installed command in a subprocess (``python -m topomatch ...``, the data root
unset), exactly as ``tests/badinput/test_corpus.py`` does; its wall time and its peak resident
memory (``ru_maxrss`` of that child, from ``os.wait4``) are recorded. Goals (issue 11): every bad
input answered in under 5 s and under 500 MB, with the expected exit status and no traceback.
A plain ``python -m topomatch --version`` is measured the same way as the floor (interpreter and
imports).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from badinput.corpus import all_cases, command_line, make_assets, write_files  # noqa: E402


def measure(argv: list[str], cwd: Path) -> dict:
    """Exit status, output, seconds and peak RSS (MB) of ``python -m topomatch argv``."""
    env = dict(os.environ)
    env.pop("TOPOMATCH_DATA_ROOT", None)
    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([sys.executable, "-m", "topomatch", *argv], stdout=out, stderr=err, cwd=cwd, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        text = err.read().decode(errors="replace") + out.read().decode(errors="replace")
    return {"code": proc.returncode, "seconds": round(seconds, 3), "peak_mb": round(usage.ru_maxrss / 1024, 1),
            "output": text}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="write every case's measurements to this JSON file")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)

        def run(argv: list[str]) -> None:
            done = measure(argv, root)
            if done["code"] != 0:
                raise SystemExit(f"asset command failed: {argv}\n{done['output']}")

        assets = make_assets(root / "assets", run)
        floor = measure(["--version"], root)
        rows = []
        for i, case in enumerate(all_cases()):
            d = root / f"case{i}"
            d.mkdir()
            write_files(case, d, assets)
            m = measure(command_line(case, d), d)
            ok = (m["code"] == case.code and "Traceback" not in m["output"]
                  and re.search(case.message, m["output"]) is not None)
            rows.append({"id": case.id, "kind": case.kind, "code": m["code"], "expected": case.code, "as_expected": ok,
                         "seconds": m["seconds"], "peak_mb": m["peak_mb"]})
            print(f"{case.id:45s} {m['code']} {'ok ' if ok else 'BAD'} {m['seconds']:6.2f} s {m['peak_mb']:7.1f} MB",
                  flush=True)
            if not ok:
                print("    " + m["output"][-1500:].replace("\n", "\n    "), flush=True)
    slowest = max(rows, key=lambda r: r["seconds"])
    biggest = max(rows, key=lambda r: r["peak_mb"])
    summary = {"cases": len(rows), "as_expected": sum(r["as_expected"] for r in rows),
               "over_5_s": [r["id"] for r in rows if r["seconds"] >= 5.0],
               "over_500_mb": [r["id"] for r in rows if r["peak_mb"] >= 500.0],
               "slowest": slowest, "largest": biggest,
               "floor_version_command": {"seconds": floor["seconds"], "peak_mb": floor["peak_mb"]}}
    print(json.dumps(summary, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps({"summary": summary, "cases": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
