"""Shared fixtures: the repository's bundled data."""

from __future__ import annotations

import pytest

from tests_paths import BUNDLED_MESHES


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
