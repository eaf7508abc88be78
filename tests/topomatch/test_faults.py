"""Faults as they happen to a user: a killed command leaves no worker processes behind, and the same
command resumes without losing or recomputing finished work."""

from __future__ import annotations

import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from tests_paths import BUNDLED_MESHES


def _tagged_processes(tag: str) -> list[int]:
    """Pids of the live processes whose environment holds ``TOPOMATCH_TEST_TAG=tag``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            env = (entry / "environ").read_bytes()
            state = (entry / "stat").read_text().split()[2]
        except OSError:
            continue
        if f"TOPOMATCH_TEST_TAG={tag}".encode() in env and state != "Z":
            found.append(int(entry.name))
    return found


def _rows(db: Path) -> int:
    try:
        return sqlite3.connect(db).execute("SELECT COUNT(*) FROM shapes").fetchone()[0]
    except sqlite3.Error:
        return 0


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")
def test_killed_index_leaves_no_workers_and_resumes(tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    for name in ["torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz", "odedstein_cat-low-resolution.obj.gz",
                 "odedstein_koala_low_resolution.obj.gz", "odedstein_fish_low_resolution.obj.gz",
                 "odedstein_spot_low_resolution.obj.gz", "odedstein_human_man.obj.gz"]:
        shutil.copy(BUNDLED_MESHES / name, folder / name)
    db = tmp_path / "index.db"
    tag = uuid.uuid4().hex
    env = {**os.environ, "TOPOMATCH_TEST_TAG": tag}
    cmd = [sys.executable, "-m", "topomatch", "index", str(folder), "--db", str(db), "--method", "sh", "--workers", "2",
           "--no-progress"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while _rows(db) < 2 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, "the index finished before it could be killed"
    assert len(_tagged_processes(tag)) >= 2  # the command and its workers
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done = _rows(db)
    deadline = time.time() + 10
    while _tagged_processes(tag) and time.time() < deadline:
        time.sleep(0.2)
    assert _tagged_processes(tag) == [], "worker processes outlived the killed command"
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert f"{8 - done} indexed, 0 failed, {done} unchanged" in out.stdout
    assert _rows(db) == 8
