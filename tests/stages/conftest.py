"""Fixtures of the stage tests: the synthetic shapes of :mod:`shapes`."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from shapes import disjoint_union, icosphere, octahedron, soup, unit_cube


@pytest.fixture
def shapes():
    """Builders of small test meshes: octahedron, icosphere, unit_cube, disjoint_union, soup."""
    return SimpleNamespace(octahedron=octahedron, icosphere=icosphere, unit_cube=unit_cube,
                           disjoint_union=disjoint_union, soup=soup)
