"""Faults as they happen to a user: a killed command leaves no worker processes behind, and the same
command resumes without losing or recomputing finished work."""

from __future__ import annotations

import json
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
from processes import tagged_processes
from tests_paths import BUNDLED_MESHES


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
    assert len(tagged_processes(tag)) >= 2  # the command and its workers
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done = _rows(db)
    deadline = time.time() + 10
    while tagged_processes(tag) and time.time() < deadline:
        time.sleep(0.2)
    assert tagged_processes(tag) == [], "worker processes outlived the killed command"
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert f"{8 - done} indexed, 0 failed, {done} unchanged" in out.stdout
    assert _rows(db) == 8


def _cache_entries(cache: Path) -> int:
    return sum(1 for p in cache.rglob("*.npz")) if cache.exists() else 0


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")
def test_killed_run_leaves_no_workers_is_marked_incomplete_and_resumes(tmp_path):
    import csv

    import yaml

    meshes = ["torus.off", "eight_genus2.off", "odedstein_hand_lowres.obj.gz", "odedstein_cat-low-resolution.obj.gz",
              "odedstein_koala_low_resolution.obj.gz", "odedstein_fish_low_resolution.obj.gz",
              "odedstein_spot_low_resolution.obj.gz", "odedstein_human_man.obj.gz"]
    config = {"name": "killed", "inputs": {"meshes": [str(BUNDLED_MESHES / m) for m in meshes]},
              "executor": {"kind": "local", "workers": 2},
              "stages": ["load", "clean", "morse", "level_sets", "reeb_graph", "prune", "measures"]}
    path = tmp_path / "killed.yaml"
    path.write_text(yaml.safe_dump(config))
    out, cache = tmp_path / "runs", tmp_path / "runs" / ".cache"
    tag = uuid.uuid4().hex
    env = {**os.environ, "TOPOMATCH_TEST_TAG": tag}
    cmd = [sys.executable, "-m", "topomatch", "run", str(path), "--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while _cache_entries(cache) < 8 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    stored = _cache_entries(cache)
    deadline = time.time() + 10
    while tagged_processes(tag) and time.time() < deadline:
        time.sleep(0.2)
    assert tagged_processes(tag) == [], "worker processes outlived the killed run"
    (run_dir,) = [p for p in out.iterdir() if p.name.startswith("killed-")]
    assert (run_dir / "INCOMPLETE").is_file() and not (run_dir / "tables" / "results.csv").exists()

    resumed = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    assert not (run_dir / "INCOMPLETE").exists()
    manifest = json.loads((run_dir / "manifest.json").read_text())
    hits = sum(1 for item in manifest["items"] for hit in item["cache_hits"].values() if hit)
    assert hits >= stored - 2  # everything stored before the kill was reused (entries being written may be lost)
    with open(run_dir / "tables" / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    # the resumed tables equal an uninterrupted run's (timings aside)
    fresh = subprocess.run([sys.executable, "-m", "topomatch", "run", str(path), "--out", str(tmp_path / "fresh"),
                            "--no-progress", "--no-cache"], env=env, capture_output=True, text=True, timeout=600)
    assert fresh.returncode == 0, fresh.stderr
    (fresh_dir,) = list((tmp_path / "fresh").iterdir())
    with open(fresh_dir / "tables" / "results.csv", newline="") as fh:
        expected = list(csv.DictReader(fh))
    untimed = [k for k in expected[0] if "seconds" not in k]
    assert [{k: r[k] for k in untimed} for r in rows] == [{k: r[k] for k in untimed} for r in expected]
