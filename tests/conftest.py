"""Shared fixtures: the repository's bundled data."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
BUNDLED_MESHES = REPO_ROOT / "data" / "meshes"


@pytest.fixture
def bundled_mesh():
    """``bundled_mesh(name)`` reads ``data/meshes/<name>`` of this repository into a Mesh."""
    from stages.mesh.io import read_mesh

    def load(name: str):
        path = BUNDLED_MESHES / name
        if not path.is_file():
            pytest.fail(f"bundled mesh {path} is missing")
        return read_mesh(path)[0]

    return load
