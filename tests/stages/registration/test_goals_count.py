"""The goal counter of the report splits (`benchmarks/registration_goals.py`) on rows whose verdicts are known."""

import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "benchmarks"))
import registration_goals as goals  # noqa: E402


def _row(case, method, tre, ok, unit=1.0, dim=2):
    return {"case": case, "method": method, "tre": tre, "ok": ok, "unit": unit, "dim": dim}


def test_each_goal_is_counted_as_the_goals_read():
    # case a: all right and passed; b: JT silent (1.5 px), MI refused and right (a false flag), elastix right;
    # c: 2 mm pixels, JT 1.8 mm (0.9 px: right) passed, MI right, elastix gave no transform.
    rows = [_row("a", "ours-jt", 0.1, True), _row("a", "ours-mi", 0.2, True), _row("a", "elastix", 0.3, True),
            _row("b", "ours-jt", 1.5, True), _row("b", "ours-mi", 0.5, False), _row("b", "elastix", 0.4, True),
            _row("c", "ours-jt", 1.8, True, 2.0), _row("c", "ours-mi", 0.6, True, 2.0), _row("c", "elastix", None, True, 2.0)]
    v = goals.verdicts(rows, 2)
    assert v["cases"] == 3
    assert v["ours-jt"] == {"silent": 1, "false_flags": 0, "misses_where_elastix_right": 1}
    assert v["ours-mi"] == {"silent": 0, "false_flags": 1, "misses_where_elastix_right": 0}
    assert v["median"] == {"ours-jt": 1.5, "elastix": 0.4}  # elastix: 0.3, 0.4 and an infinite error
    assert v["met"] == {"silent": False, "within_1": False, "false_flags": False, "median": False}
    finished = goals.verdicts(rows, 2, finished=True)["median"]["elastix"]
    assert math.isclose(finished, 0.35)  # over its two finished runs
