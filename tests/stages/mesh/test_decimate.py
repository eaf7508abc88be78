"""Decimation reaches its target, is independent of units, and validates its parameters."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from topomatch.pipeline.errors import ConfigError, StageError
from topomatch.stages.mesh.decimate import DecimateParams, decimate, decimate_mesh, target_tolerance
from topomatch.stages.mesh.measures import bbox_diagonal
from topomatch.stages.mesh.mesh import Mesh


def _assert_reached(result, target):
    assert result.faces_after <= target + target_tolerance(target)
    assert result.faces_after >= target - target_tolerance(target)


@pytest.mark.parametrize("name", ["torus.off", "eight_genus2.off", "odedstein_spot_low_resolution.obj.gz",
                                  "odedstein_hand_lowres.obj.gz"])
@pytest.mark.parametrize("ratio", [0.5, 0.1, 0.02])
def test_ratio_reaches_the_target(bundled_mesh, name, ratio):
    mesh = bundled_mesh(name)
    result = decimate(mesh, params=DecimateParams(ratio=ratio))
    target = round(ratio * mesh.n_faces)
    assert result.target == target and result.faces_before == mesh.n_faces
    _assert_reached(result, target)
    assert result.faces_after == result.mesh.n_faces
    # no unreferenced vertices, valid indices
    assert np.array_equal(np.unique(result.mesh.F), np.arange(result.mesh.n_vertices))
    assert result.mesh.name == mesh.name


def test_target_faces_on_a_closed_mesh_is_met_up_to_parity(bundled_mesh):
    mesh = bundled_mesh("torus.off")
    for target in (1000, 333, 100):
        result = decimate(mesh, params=DecimateParams(target_faces=target))
        # an interior collapse removes 2 faces of a closed mesh: the count stays even
        assert result.faces_after in (target, target - 1)
        assert result.faces_after % 2 == 0


def test_moderate_decimation_keeps_the_topology_of_the_torus(bundled_mesh):
    from topomatch.stages.mesh.topology import topology_report

    result = decimate(bundled_mesh("torus.off"), params=DecimateParams(ratio=0.2))
    assert (result.euler_before, result.euler_after, result.nonmanifold_edges_after) == (0, 0, 0)
    assert topology_report(result.mesh).genus == 1


@pytest.mark.parametrize("scale,shift", [(1000.0, (5.0, -3.0, 2.0)), (1e-3, (0.0, 0.0, 0.0))])
def test_units_do_not_matter(bundled_mesh, scale, shift):
    """fast-simplification's threshold is absolute; the stage normalises the mesh so the result is unit-free."""
    import igl

    mesh = bundled_mesh("torus.off")
    target = 48
    ref = decimate_mesh(mesh, target)
    moved = decimate_mesh(Mesh(mesh.V * scale + np.array(shift), mesh.F), target)
    _assert_reached(moved, target)
    back = (moved.mesh.V - np.array(shift)) / scale
    assert igl.hausdorff(back, moved.mesh.F, ref.mesh.V, ref.mesh.F) < 1e-6 * bbox_diagonal(mesh.V)


def test_decimated_shape_stays_close_to_the_input(bundled_mesh):
    import igl

    mesh = bundled_mesh("eight_genus2.off")
    result = decimate(mesh, params=DecimateParams(ratio=0.5))
    # measured 0.0056 of the diagonal; a collapse moves vertices by a fraction of the edge length (~4%)
    assert igl.hausdorff(mesh.V, mesh.F, result.mesh.V, result.mesh.F) < 0.01 * bbox_diagonal(mesh.V)


def test_target_above_the_face_count_returns_the_input(shapes):
    octa = shapes.octahedron()
    result = decimate(octa, params=DecimateParams(target_faces=100))
    assert result.mesh is octa and result.passes == 0 and result.faces_after == 8


def test_stalling_is_a_stage_error(bundled_mesh):
    # with agg=1 the collapse threshold never grows past ~1e-7 of the diagonal squared: the torus barely moves
    with pytest.raises(StageError, match="torus: fast-simplification stopped at"):
        decimate(bundled_mesh("torus.off"), params=DecimateParams(target_faces=48, aggressiveness=1.0))


def test_exactly_one_target_is_required():
    with pytest.raises(ValidationError, match="exactly one of target_faces and ratio"):
        DecimateParams()
    with pytest.raises(ValidationError, match="both given"):
        DecimateParams(target_faces=100, ratio=0.5)
    with pytest.raises(ConfigError, match=r"stages\[2\].decimate: .*neither given"):
        DecimateParams.parse({}, "stages[2].decimate")
    with pytest.raises(ConfigError, match="both given"):
        DecimateParams.parse({"target_faces": 100, "ratio": 0.5}, "stages[2].decimate")
    assert DecimateParams.parse({"ratio": 1}, "s").target_for(10) == 10


@pytest.mark.parametrize("bad", [{"ratio": 0.0}, {"ratio": 1.5}, {"ratio": "0.5"}, {"target_faces": 3},
                                 {"target_faces": 10.0}, {"target_faces": 10, "aggressiveness": 0}])
def test_invalid_values_are_rejected(bad):
    with pytest.raises(ConfigError, match=r"^stages\[2\].decimate\."):
        DecimateParams.parse(bad, "stages[2].decimate")
