"""The CLI as a user meets it: exit codes and one-line messages that name the file and the problem."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from tests_paths import REPO_ROOT


def topomatch(*args, cwd=None):
    """The command, run from ``cwd`` (default: here) on this checkout (not whatever the environment installed)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO_ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "topomatch", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


def test_help_everywhere():
    for args in ([], ["run"], ["validate"], ["stages"]):
        r = topomatch(*args, "--help")
        assert r.returncode == 0 and "usage: topomatch" in r.stdout


def test_stages_lists_every_stage_with_params():
    r = topomatch("stages", "--json")
    assert r.returncode == 0
    listing = json.loads(r.stdout)
    assert {"load", "clean", "decimate", "noise", "transform", "measures"} <= set(listing["stages"])
    noise = {p["name"]: p for p in listing["stages"]["noise"]["params"]}
    assert noise["sigma"]["type"] == "float"
    assert listing["inputs"]["pairs"]["provides"] == ["fixed_path", "moving_path", "truth"]
    assert listing["inputs"]["meshes"]["type"] == "list[str]"
    text = topomatch("stages").stdout
    assert "decimate" in text and "relative_to" in text and "  pairs_csv: PairsCsvConfig | None" in text


def test_missing_config_file(tmp_path):
    r = topomatch("run", tmp_path / "nope.yaml", "--out", tmp_path)
    assert r.returncode == 1
    assert "nope.yaml: config file not found" in r.stderr
    assert "Traceback" not in r.stderr


def test_missing_mesh_file(small_config, write_config, tmp_path):
    small_config["inputs"]["meshes"] = [str(tmp_path / "gone.off")]
    r = topomatch("run", write_config(small_config), "--out", tmp_path)
    assert r.returncode == 1
    assert "gone.off: file not found" in r.stderr and "Traceback" not in r.stderr


def test_malformed_off_fails_its_item_and_keeps_the_others(small_config, write_config, tmp_path):
    bad = tmp_path / "malformed.off"
    bad.write_text("OFF\n4 2 0\n0 0 0\n1 0 0\n0 1\n")
    small_config["inputs"]["meshes"].append(str(bad))
    small_config["sweep"] = {}
    r = topomatch("run", write_config(small_config), "--out", tmp_path / "runs", "--no-progress")
    assert r.returncode == 1
    assert "1 of 3 items failed" in r.stderr and "malformed.off: malformed OFF file" in r.stderr
    assert "Traceback" not in r.stderr
    results = list((tmp_path / "runs").glob("small-*/tables/results.csv"))
    assert results and results[0].read_text().count("\n") == 4  # header + 3 rows, 2 of them ok


def test_unknown_config_key(small_config, write_config):
    small_config["stages"][1] = {"clean": {"merge_tolerence": 0.1}}
    r = topomatch("validate", write_config(small_config, "typo"))
    assert r.returncode == 2
    assert "typo.yaml: stages[1].clean.merge_tolerence: unknown key" in r.stderr
    assert "Traceback" not in r.stderr


def test_wrong_type(small_config, write_config):
    small_config["stages"][2] = {"noise": {"sigma": "a lot"}}
    r = topomatch("validate", write_config(small_config))
    assert r.returncode == 2
    assert "stages[2].noise.sigma: Input should be a valid number, got 'a lot'" in r.stderr


def test_bad_override_value(small_config, write_config):
    r = topomatch("validate", write_config(small_config), "--set", "noise.seed=1.5")
    assert r.returncode == 2 and "stages[2].noise.seed" in r.stderr


def test_debug_shows_traceback(tmp_path):
    r = topomatch("--debug", "validate", tmp_path / "nope.yaml")
    assert r.returncode != 0 and "Traceback" in r.stderr


def test_validate_ok(small_config, write_config):
    r = topomatch("validate", write_config(small_config))
    assert r.returncode == 0 and "ok (small: 2 inputs, 2 sweep points, 4 stages" in r.stdout


@pytest.mark.slow
def test_run_then_rerun_hits_the_cache(small_config, write_config, tmp_path):
    cfg = write_config(small_config)
    first = topomatch("run", cfg, "--out", tmp_path / "runs", "--no-progress")
    assert first.returncode == 0, first.stderr
    second = topomatch("run", cfg, "--out", tmp_path / "runs", "--no-progress")
    assert "cache hits 16/16" in second.stdout


_MMAPPED_BYTES = """
import ctypes, sys
import numpy as np
class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                               "fsmblks", "uordblks", "fordblks", "keepcost")]
libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
if sys.argv[1] == "keep":
    from topomatch.cli.allocator import keep_freed_memory
    assert keep_freed_memory()
a = np.ones(2 << 20)  # 16 MiB
print(int(libc.mallinfo2().hblkhd >= a.nbytes))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt and mallinfo2")
def test_the_command_serves_large_arrays_from_the_heap():
    """After the CLI's allocator settings a 16 MiB array comes from the (reusable) heap, not from a fresh
    mmap as by default (glibc's own count of mmapped bytes, in new processes)."""
    import ctypes

    if not hasattr(ctypes.CDLL(None), "mallinfo2"):
        pytest.skip("glibc older than 2.33")
    mmapped = {how: subprocess.run([sys.executable, "-c", _MMAPPED_BYTES, how], capture_output=True, text=True,
                                   check=True).stdout.strip() for how in ("default", "keep")}
    assert mmapped == {"default": "1", "keep": "0"}


def test_a_closed_stdout_pipe_ends_the_command_quietly():
    """`topomatch stages | head -1`: the reader leaves before the listing is written; the command stops with
    128 + SIGPIPE and no traceback (it printed one through Python's final flush before)."""
    proc = subprocess.Popen([sys.executable, "-m", "topomatch", "stages"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # long before the interpreter has started and imported the stages
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 141
    assert b"Traceback" not in err and b"Broken pipe" not in err


def test_python_warnings_read_as_the_commands_own(capsys):
    # the command shows a Python warning (e.g. a cache entry it recomputes) as `topomatch: warning: ...`, hidden
    # by -q, with its source only under -vv
    from topomatch.cli import _show_warning, common

    message = UserWarning("cache entry x.npz is unusable (bad zip); recomputing")
    for level, expected in ((0, f"topomatch: warning: {message}\n"), (-1, ""),
                            (2, f"topomatch: warning: {message} (UserWarning at cache.py:73)\n")):
        common.reset(level)
        _show_warning(message, UserWarning, "cache.py", 73)
        assert capsys.readouterr().err == expected
    common.reset(0)


def test_the_command_reports_a_recomputed_cache_entry_as_its_own_warning(tmp_path):
    # end to end: `topomatch query` meets cache entries it cannot read, recomputes them and says so in its own
    # form (Python's display printed the file, the line and the source of the warnings.warn call)
    from tests_paths import BUNDLED_MESHES

    db, mesh = tmp_path / "i.db", BUNDLED_MESHES / "torus.off"
    assert topomatch("index", mesh, "--db", db, "--method", "d2", "--no-progress").returncode == 0

    def corrupt_cache():
        entries = list((tmp_path / "i.db.cache").rglob("*.npz"))
        assert entries
        for entry in entries:
            entry.write_bytes(b"not a cache entry")

    corrupt_cache()
    done = topomatch("query", mesh, "--db", db, "--method", "d2")
    assert done.returncode == 0 and "topomatch: warning: cache entry" in done.stderr and "recomputing" in done.stderr
    assert "warnings.warn" not in done.stderr and "CacheWarning" not in done.stderr
    corrupt_cache()
    done = topomatch("-q", "query", mesh, "--db", db, "--method", "d2")
    assert done.returncode == 0 and done.stderr == "" and "torus.off" in done.stdout


def test_bundled_names_work_from_any_folder_and_an_unknown_one_names_the_closest(tmp_path):
    r = topomatch("skeleton", "bundled:torus.off", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["mesh"].endswith("/meshes/torus.off") and json.loads(r.stdout)["cycle_rank"] == 1
    r = topomatch("match", "bundled:meshes/torus.off", "bundled:nope.off", cwd=tmp_path)
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert r.stderr.startswith("topomatch: error: bundled:nope.off: not among the bundled data")
    assert "closest: meshes/torus.off" in r.stderr
    r = topomatch("index", "bundled:meshes", "--db", tmp_path / "s.db", "--labels", "bundled:../pyproject.toml",
                  "--json")
    assert r.returncode == 1 and "Traceback" not in r.stderr
    error = json.loads(r.stdout)
    assert error["kind"] == "input" and error["file"] == "bundled:../pyproject.toml" and "outside" in error["error"]
    assert not (tmp_path / "s.db").exists()  # refused while reading the command line, before any work


def test_every_input_argument_takes_bundled_names():
    """``common.input_path`` is where the command line resolves ``bundled:NAME``: every input file or folder
    argument uses it (configs are found by name instead: ``topomatch configs``)."""
    from topomatch.cli import build_parser
    from topomatch.cli.common import input_path

    inputs = set()
    for command in ("skeleton", "match", "index", "query", "evaluate", "register", "run", "validate", "thesis"):
        sub = build_parser(command)._subparsers._group_actions[0].choices[command]
        inputs |= {(command, a.dest) for a in sub._actions if a.type is input_path}
    assert inputs == {("skeleton", "mesh"), ("match", "a"), ("match", "b"), ("index", "paths"), ("index", "labels"),
                      ("query", "mesh"), ("register", "fixed"), ("register", "moving")}
