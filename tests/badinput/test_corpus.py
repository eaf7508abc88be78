"""Every case of the bad-input corpus (``corpus.py``, 150+ cases) as a user meets it: the installed
command in a subprocess; the exit status and the message are asserted, and no traceback may be
printed. (Time and memory per case are measured by ``benchmarks/bad_inputs.py``, not here.)"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from badinput.corpus import Case, all_cases, command_line, make_assets, write_files

CASES = all_cases()
HANG_GUARD_S = 120  # a case still running after this is a hang


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("TOPOMATCH_DATA_ROOT", None)  # the corpus is self-contained; warnings show as a user sees them
    return env


def run_topomatch(argv: list[str], cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "topomatch", *argv], capture_output=True, text=True, env=_env(),
                          cwd=cwd, timeout=HANG_GUARD_S)


@pytest.fixture(scope="session")
def assets(tmp_path_factory) -> dict[str, Path]:
    def run(argv: list[str]) -> None:
        done = run_topomatch(argv)
        assert done.returncode == 0, done.stderr

    return make_assets(tmp_path_factory.mktemp("assets"), run)


def test_the_corpus_is_large_and_covers_every_kind():
    kinds = {c.kind for c in CASES}
    assert len(CASES) >= 150 and kinds == {"mesh", "config", "image", "cli", "database", "cache"}


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(case: Case, tmp_path, assets):
    write_files(case, tmp_path, assets)
    done = run_topomatch(command_line(case, tmp_path), cwd=tmp_path)
    output = done.stderr + done.stdout
    assert "Traceback" not in output, output[-3000:]
    assert done.returncode == case.code, f"exit {done.returncode}, expected {case.code}:\n{output[-2000:]}"
    assert re.search(case.message, output), f"message {case.message!r} not in:\n{output[-2000:]}"
