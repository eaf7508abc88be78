"""Atomic writes: readers see the old file or the new one, and an error names the path the caller gave, never
the temporary file beside it."""

from __future__ import annotations

import os

import pytest

from topomatch.pipeline.cache import hash_file
from topomatch.pipeline.files import atomic_write_text


def test_a_name_as_long_as_the_file_system_allows_is_written(tmp_path):
    path = tmp_path / ("t" * 251 + ".csv")  # 255 bytes: the temporary name beside it must not be longer
    atomic_write_text(path, "a,b\n")
    assert path.read_text() == "a,b\n" and os.listdir(tmp_path) == [path.name]


def test_errors_name_the_callers_path(tmp_path):
    (tmp_path / "overlay.png").mkdir()
    with pytest.raises(IsADirectoryError) as exc:
        atomic_write_text(tmp_path / "overlay.png", "x")
    assert exc.value.filename == str(tmp_path / "overlay.png") and ".tmp" not in str(exc.value)
    (tmp_path / "f").write_text("a file")
    with pytest.raises(NotADirectoryError) as exc:
        atomic_write_text(tmp_path / "f" / "sub" / "table.csv", "x")
    assert exc.value.filename == str(tmp_path / "f" / "sub" / "table.csv") and ".tmp" not in str(exc.value)
    with pytest.raises(OSError) as exc:
        atomic_write_text(tmp_path / ("t" * 300 + ".csv"), "x")  # too long for any file system
    assert exc.value.filename.endswith("t.csv") and ".tmp" not in str(exc.value)
    assert sorted(os.listdir(tmp_path)) == ["f", "overlay.png"]  # no temporary file left behind


def test_inputs_that_would_block_are_refused_and_folders_are_hashed_by_their_files(tmp_path):
    os.mkfifo(tmp_path / "pipe.nii.gz")
    with pytest.raises(OSError, match="not a regular file"):
        hash_file(tmp_path / "pipe.nii.gz")  # reading it would wait for a writer forever
    series = tmp_path / "series"
    series.mkdir()
    (series / "a.dcm").write_bytes(b"1")
    (series / "b.dcm").write_bytes(b"2")
    before = hash_file(series)
    (series / "b.dcm").write_bytes(b"3")
    assert hash_file(series) != before  # a slice changed: another cache key
