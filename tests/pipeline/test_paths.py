"""Naming the bundled data: ``topomatch.data_path(NAME)`` in Python, ``bundled:NAME`` on the command line."""

from __future__ import annotations

import pytest

import topomatch
from topomatch.pipeline import paths
from topomatch.pipeline.errors import InputError
from topomatch.pipeline.paths import data_path
from tests_paths import BUNDLED_MESHES, ITK_DIR, REPO_ROOT


def test_a_bundled_file_by_its_name_or_its_path_under_the_data_folder():
    torus = (BUNDLED_MESHES / "torus.off").resolve()
    assert data_path("torus.off") == data_path("meshes/torus.off") == data_path("bundled:torus.off") == torus
    assert topomatch.data_path is data_path  # the public name, loaded on first use
    assert "data_path" in topomatch.__all__


def test_nested_names_and_folders():
    slice_png = (ITK_DIR / "BrainT1Slice.png").resolve()
    assert data_path("images/itk/BrainT1Slice.png") == data_path("itk/BrainT1Slice.png") == slice_png
    assert data_path("meshes") == BUNDLED_MESHES.resolve() and data_path("meshes").is_dir()
    assert data_path() == data_path("bundled:") == (REPO_ROOT / "data").resolve()
    assert "meshes/labels.csv" in paths.bundled_files() and "images/itk/BrainT1Slice.png" in paths.bundled_files()


def test_an_unknown_name_is_an_input_error_naming_it_and_the_closest_bundled_files():
    with pytest.raises(InputError) as err:
        data_path("tours.off")
    assert err.value.path == "bundled:tours.off"
    assert str(err.value).startswith("bundled:tours.off: not among the bundled data")
    assert "closest: meshes/torus.off" in str(err.value)
    with pytest.raises(InputError, match=r"bundled:BrainT1\.png: .*closest: images/itk/BrainT1Slice\.png"):
        data_path("BrainT1.png")
    with pytest.raises(InputError, match=r"bundled:zzz: not among the bundled data .*it holds \d+ files under"):
        data_path("zzz")


@pytest.mark.parametrize("name", ["../pyproject.toml", "meshes/../../pyproject.toml", "/etc/passwd",
                                  "bundled:../README.md"])
def test_a_name_outside_the_data_folder_is_refused(name):
    assert (REPO_ROOT / "pyproject.toml").is_file()  # it exists: refused for where it is, not for being missing
    with pytest.raises(InputError, match="outside the bundled data folder .*: refused"):
        data_path(name)


def test_a_file_name_held_twice_must_be_named_by_its_folder(tmp_path, monkeypatch):
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "x.off").write_text("OFF\n")
    (tmp_path / "__pycache__").mkdir()
    (tmp_path / "__pycache__" / "y.pyc").write_bytes(b"")
    monkeypatch.setattr(paths, "BUNDLED_DIR", tmp_path)
    with pytest.raises(InputError, match=r"bundled:x\.off: several bundled files end so: a/x\.off, b/x\.off"):
        data_path("x.off")
    assert data_path("b/x.off") == (tmp_path / "b" / "x.off").resolve()
    assert paths.bundled_files() == ["a/x.off", "b/x.off"]
