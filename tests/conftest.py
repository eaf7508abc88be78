"""Shared fixtures: the repository's bundled data (meshes, ITK brain slices) and small configs."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from tests_paths import BUNDLED_MESHES, ITK_DIR


@pytest.fixture
def bundled_mesh():
    """``bundled_mesh(name)`` reads ``data/meshes/<name>`` of this repository into a Mesh."""
    from topomatch.stages.mesh.io import read_mesh

    def load(name: str):
        path = BUNDLED_MESHES / name
        if not path.is_file():
            pytest.fail(f"bundled mesh {path} is missing")
        return read_mesh(path)[0]

    return load


@pytest.fixture(scope="session")
def itk_dir() -> Path:
    return ITK_DIR


@pytest.fixture(scope="session")
def pd_slice():
    """BrainProtonDensitySlice.png (217 x 181), the bundled ITK proton-density slice."""
    from topomatch.stages.registration.io import read_image

    return read_image(ITK_DIR / "BrainProtonDensitySlice.png")


@pytest.fixture
def write_config(tmp_path):
    """Write a config mapping to tmp_path/<name>.yaml and return the path."""

    def write(data: dict, name: str = "config") -> Path:
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        return path

    return write


@pytest.fixture
def small_config() -> dict:
    """Two bundled meshes, a two-point noise sweep, load -> clean -> noise -> measures."""
    return {
        "name": "small",
        "inputs": {"meshes": [str(BUNDLED_MESHES / "torus.off"), str(BUNDLED_MESHES / "eight_genus2.off")]},
        "sweep": {"noise.sigma": [0.0, 0.01]},
        "stages": [
            "load",
            {"clean": {}},
            {"noise": {"sigma": 0.0, "relative_to": "bbox_diagonal", "seed": 3}},
            "measures",
        ],
        "executor": {"kind": "local", "workers": 1},
    }
