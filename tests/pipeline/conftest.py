"""Fixtures for engine tests: small configs written into tmp_path."""

from __future__ import annotations

import pytest
import yaml

from tests_paths import BUNDLED_MESHES


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
