"""Mesh measures: exact areas and edge statistics, equal to open3d's."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.registry import get_stage
from topomatch.stages.mesh.measures import MeasuresParams, measures, mesh_measures
from topomatch.stages.mesh.mesh import Mesh


def test_unit_cube(shapes):
    m = mesh_measures(shapes.unit_cube())
    assert m.area == 6.0 and m.area_open3d == pytest.approx(6.0, rel=1e-15)
    assert (m.n_vertices, m.n_faces, m.n_edges) == (8, 12, 18)
    assert m.bbox_min == (0.0, 0.0, 0.0) and m.bbox_max == (1.0, 1.0, 1.0)
    assert m.bbox_diagonal == pytest.approx(np.sqrt(3))
    assert (m.edge_min, m.edge_max) == (1.0, pytest.approx(np.sqrt(2)))


def test_right_triangle():
    tri = Mesh(np.array([[0, 0, 0], [3, 0, 0], [0, 4, 0]], float), np.array([[0, 1, 2]]), name="tri")
    m = mesh_measures(tri)
    assert m.area == 6.0 and m.area_open3d == 6.0 and m.area_rel_diff == 0.0
    assert (m.edge_min, m.edge_max, m.edge_mean) == (3.0, 5.0, 4.0)
    assert m.edge_std == pytest.approx(np.sqrt(2 / 3))  # population std of 3, 4, 5
    assert m.bbox_diagonal == 5.0


def test_octahedron_area_is_analytic(shapes):
    # 8 equilateral triangles of side sqrt(2): 8 * sqrt(3)/4 * 2 = 4 sqrt(3)
    m = mesh_measures(shapes.octahedron())
    assert m.area == pytest.approx(4 * np.sqrt(3), rel=1e-14)
    assert m.edge_std == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize("name", ["torus.off", "odedstein_cat-low-resolution.obj.gz"])
def test_libigl_and_open3d_areas_agree(bundled_mesh, name):
    m = mesh_measures(bundled_mesh(name))
    assert m.area_rel_diff < 1e-12
    assert m.n_edges == m.n_vertices + m.n_faces - (2 if "cat" in name else 0)  # chi = 2 (sphere) / 0 (torus)


def test_stage_passes_the_mesh_through(shapes):
    result = measures(shapes.unit_cube(), params=MeasuresParams())
    assert result.summary()["area"] == 6.0
    assert get_stage("measures").produces == ()


def test_open3d_adapter_round_trip(bundled_mesh):
    from topomatch.stages.adapters.open3d_adapter import from_open3d, to_open3d

    mesh = bundled_mesh("eight_genus2.off")
    back = from_open3d(to_open3d(mesh), name="x")
    np.testing.assert_array_equal(back.V, mesh.V)
    np.testing.assert_array_equal(back.F, mesh.F)
    assert back.F.dtype == np.int64 and back.name == "x"
