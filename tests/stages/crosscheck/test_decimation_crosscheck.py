"""fast-simplification and MeshLab decimate to the same face count and nearly the same shape."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.registry import get_stage
from topomatch.stages.crosscheck.decimation import DecimationCrosscheckParams, decimate_crosscheck, meshlab_decimate
from topomatch.stages.mesh.decimate import DecimateParams, decimate, target_tolerance


@pytest.mark.parametrize("name,ratio", [("torus.off", 0.5), ("eight_genus2.off", 0.5), ("torus.off", 0.2),
                                        ("odedstein_hand_lowres.obj.gz", 0.5)])
def test_both_decimations_agree(bundled_mesh, name, ratio):
    mesh = bundled_mesh(name)
    result = decimate_crosscheck(mesh, params=DecimationCrosscheckParams(ratio=ratio))
    s = result.summary()
    target = round(ratio * mesh.n_faces)
    assert s["target"] == target
    for faces in (s["faces_fast"], s["faces_meshlab"]):
        assert abs(faces - target) <= target_tolerance(target)
    # Measured (relative to the bbox diagonal): fast vs MeshLab 0.0019 / 0.0068 / 0.0065 / 0.0064, each within
    # 0.006 of the input. Two independent quadric decimations each at distance h of the input can be up
    # to ~2h apart; 0.02 leaves room for that and still fails on a wrong target or a broken adapter.
    assert s["hausdorff_rel"] < 0.02
    assert s["hausdorff_fast_input_rel"] < 0.01 and s["hausdorff_meshlab_input_rel"] < 0.01
    assert s["hausdorff_rel"] == pytest.approx(result.hausdorff / result.bbox_diagonal)


def test_fast_side_is_the_decimate_stage(bundled_mesh):
    mesh = bundled_mesh("eight_genus2.off")
    cross = decimate_crosscheck(mesh, params=DecimationCrosscheckParams(target_faces=400))
    stage = decimate(mesh, params=DecimateParams(target_faces=400))
    np.testing.assert_array_equal(cross.fast.F, stage.mesh.F)
    np.testing.assert_array_equal(cross.fast.V, stage.mesh.V)


def test_identical_results_have_zero_distance(shapes):
    octa = shapes.octahedron()
    result = decimate_crosscheck(octa, params=DecimationCrosscheckParams(ratio=1.0))
    assert result.hausdorff == 0.0 and result.fast.n_faces == result.meshlab.n_faces == 8


def test_meshlab_decimate_reaches_target_without_unreferenced_vertices(bundled_mesh):
    mesh = bundled_mesh("odedstein_spot_low_resolution.obj.gz")
    out = meshlab_decimate(mesh, 300)
    assert abs(out.n_faces - 300) <= target_tolerance(300)
    assert np.array_equal(np.unique(out.F), np.arange(out.n_vertices))


def test_stage_is_registered_as_a_side_branch():
    spec = get_stage("decimate_crosscheck")
    assert spec.consumes == ("mesh",) and spec.produces == ()


def test_pymeshlab_adapter_round_trip(bundled_mesh):
    from topomatch.stages.adapters.pymeshlab_adapter import from_meshset, to_meshset

    mesh = bundled_mesh("torus.off")
    ms = to_meshset(mesh)
    assert ms.current_mesh().face_number() == mesh.n_faces
    back = from_meshset(ms, name="t")
    np.testing.assert_array_equal(back.V, mesh.V)
    np.testing.assert_array_equal(back.F, mesh.F)
    assert back.F.dtype == np.int64 and back.name == "t"
