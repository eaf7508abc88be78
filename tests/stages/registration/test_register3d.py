"""3D rigid registration: conventions against SimpleITK, known transforms recovered, determinism, self-check."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests_paths import ITK_DIR

SimpleITK = pytest.importorskip("SimpleITK")


@pytest.fixture(scope="module")
def small_t1():
    """The bundled KmeansTest T1 volume (128 x 128 x 62 voxels of 2 x 2 x 3 mm) block-averaged to 4 x 4 x 3 mm."""
    from topomatch.stages.registration.volume_io import read_volume

    return read_volume(ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz").shrink((2, 2, 1))


def _sitk_image(shape=(6, 7, 8), spacing=(0.9, 1.3, 2.5), origin=(3.0, -7.0, 11.0), angle=0.4):
    import SimpleITK as sitk

    img = sitk.GetImageFromArray(np.arange(np.prod(shape), dtype=np.float32).reshape(shape))
    img.SetSpacing(spacing)
    img.SetOrigin(origin)
    c, s = math.cos(angle), math.sin(angle)
    img.SetDirection((c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0))
    return img


def test_volume_geometry_matches_simpleitk():
    from topomatch.stages.registration.volume_io import volume_from_sitk

    img = _sitk_image()
    vol = volume_from_sitk(img)
    idx = np.array([[0, 0, 0], [1.5, 2.25, 3.0], [7, 6, 5]], dtype=float)
    ours = vol.physical(idx)
    theirs = np.array([img.TransformContinuousIndexToPhysicalPoint(tuple(i)) for i in idx])
    np.testing.assert_allclose(ours, theirs, atol=1e-12)
    np.testing.assert_allclose(vol.continuous_index(ours), idx, atol=1e-12)
    corner = np.array(img.TransformContinuousIndexToPhysicalPoint((7.0, 6.0, 5.0)))
    np.testing.assert_allclose(vol.center, (np.asarray(img.GetOrigin()) + corner) / 2, atol=1e-12)
    # shrinking keeps the physical position of each block's centre
    half = vol.shrink((2, 2, 1))
    np.testing.assert_allclose(half.physical(np.zeros((1, 3)))[0], vol.physical(np.array([[0.5, 0.5, 0.0]]))[0])
    assert half.spacing == (1.8, 2.6, 2.5) and half.shape == (6, 3, 4)


def test_transform_matrix_equals_simpleitk_euler3d():
    from topomatch.stages.registration.transform3d import RigidTransform3D, euler_angles

    rng = np.random.default_rng(3)
    for _ in range(5):
        params = tuple(rng.uniform(-0.5, 0.5, 3)) + tuple(rng.uniform(-20, 20, 3))
        center = tuple(rng.uniform(-50, 50, 3))
        t = RigidTransform3D(params, center)
        e = SimpleITK.Euler3DTransform(center, *params[:3], params[3:])
        M = np.eye(4)
        M[:3, :3] = np.reshape(e.GetMatrix(), (3, 3))
        M[:3, 3] = np.asarray(e.GetTranslation()) + np.asarray(center) - M[:3, :3] @ np.asarray(center)
        np.testing.assert_allclose(t.matrix4(), M, atol=1e-12)
        pts = rng.normal(0, 60, (4, 3))
        np.testing.assert_allclose(t.apply(pts), [e.TransformPoint(tuple(p)) for p in pts], atol=1e-10)
        np.testing.assert_allclose(euler_angles(t.rotation), params[:3], atol=1e-12)
        np.testing.assert_allclose(t.inverse().apply(t.apply(pts)), pts, atol=1e-10)
        np.testing.assert_allclose(t.with_center((1.0, 2.0, 3.0)).matrix4(), t.matrix4(), atol=1e-12)


def test_tfm_round_trip(tmp_path):
    from topomatch.stages.registration.transform3d import RigidTransform3D
    from topomatch.stages.registration.volume_io import write_transform

    t = RigidTransform3D((0.1, -0.2, 0.05, 4.0, -3.0, 7.5), (10.0, 20.0, -5.0))
    write_transform(t, tmp_path / "t.tfm")
    back = RigidTransform3D.from_sitk(SimpleITK.ReadTransform(str(tmp_path / "t.tfm")), t.center)
    np.testing.assert_allclose(back.params, t.params, atol=1e-9)
    np.testing.assert_allclose(back.matrix4(), t.matrix4(), atol=1e-9)


def test_histogram_samples_outside_are_dropped_and_mass_is_kept(small_t1):
    from topomatch.stages.registration.histogram import Binning
    from topomatch.stages.registration.histogram3d import VolumeHistogram

    jh = VolumeHistogram(small_t1, small_t1, Binning.of(small_t1.data, 16), Binning.of(small_t1.data, 16),
                         center=small_t1.center, samples=3000, seed=1)
    h, n = jh(np.zeros(6))
    assert n == jh.n_samples == 3000 and h.sum() == pytest.approx(3000)
    far = np.array([0, 0, 0, 1000.0, 0, 0])
    assert jh(far)[1] == 0 and jh.overlap(far) == 0.0
    half = jh(np.array([0, 0, 0, 0.5 * small_t1.size[0] * small_t1.spacing[0], 0, 0]))
    assert 0 < half[1] < n and half[0].sum() == pytest.approx(half[1])


def test_compiled_histogram_equals_the_numpy_one(small_t1):
    """The numba kernel against the numpy path on rotated, shifted and partly outside positions, a flat (one voxel
    thick) moving volume included: same inside counts, histograms equal to round-off."""
    from topomatch.stages.registration.histogram import Binning
    from topomatch.stages.registration.histogram3d import VolumeHistogram
    from topomatch.stages.registration.histogram3d_kernel import joint_histogram

    if joint_histogram is None:
        pytest.skip("numba is not installed: the numpy path is the only one")
    rng = np.random.default_rng(3)
    flat = small_t1.shrink((1, 1, small_t1.shape[0]))
    for moving in (small_t1, flat):
        jh = VolumeHistogram(small_t1, moving, Binning.of(small_t1.data, 24), Binning.of(moving.data, 20),
                             center=small_t1.center, samples=5000, seed=2)
        for _ in range(20):
            theta = np.r_[rng.uniform(-0.4, 0.4, 3), rng.uniform(-60.0, 60.0, 3)]
            (h, n), (h_ref, n_ref) = jh(theta), jh.histogram_numpy(theta)
            assert n == n_ref
            np.testing.assert_allclose(h, h_ref, rtol=0, atol=1e-9 * max(1, n))


@pytest.mark.parametrize("index,multimodal,crop", [(0, False, False), (1, True, True)])
def test_known_transform_recovered(small_t1, index, multimodal, crop):
    from topomatch.stages.registration.misalign3d import make_case, mean_tre
    from topomatch.stages.registration.register3d import register_volumes

    case = make_case(small_t1, index, seed=11, multimodal=multimodal, crop=crop)
    reg = register_volumes(case.fixed, case.moving)
    tre = mean_tre(case.truth, reg.transform, case.fixed)
    assert tre < 1.0, (tre, reg.reason)
    assert reg.ok, reg.reason
    assert reg.transform.center == tuple(case.fixed.center)


def test_same_seed_same_result(small_t1):
    from topomatch.stages.registration.misalign3d import make_case
    from topomatch.stages.registration.register3d import Register3DParams, register_volumes

    case = make_case(small_t1, 2, seed=5, multimodal=False, crop=False)
    params = Register3DParams(check={"search": False})
    assert register_volumes(case.fixed, case.moving, params).transform.params == \
        register_volumes(case.fixed, case.moving, params).transform.params


def test_no_overlap_after_initialisation_is_flagged(small_t1):
    from topomatch.stages.registration.register3d import Register3DParams, register_volumes
    from topomatch.stages.registration.volume import Volume

    rng = np.random.default_rng(0)
    tiny = Volume(rng.normal(size=(4, 4, 4)), (1.0, 1.0, 1.0), tuple(np.asarray(small_t1.center) + 500.0))
    reg = register_volumes(small_t1, tiny, Register3DParams(transform={"init": "geometry"}))
    assert not reg.ok and "overlap" in reg.reason


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_unrelated_content_is_flagged(small_t1, seed):
    """Noise against a head: the measure at any result stays at its chance level (the samples paired at random),
    whatever optimum the optimiser settles in."""
    from topomatch.stages.registration.register3d import register_volumes

    rng = np.random.default_rng(seed)
    noise = small_t1.with_data(rng.normal(size=small_t1.shape))
    reg = register_volumes(small_t1, noise)
    assert not reg.ok, reg.summary()
    assert "chance level" in reg.reason


def test_api_registers_volumes_in_memory_and_refuses_mixed_inputs(small_t1):
    import topomatch
    from topomatch.stages.registration.misalign3d import make_case, mean_tre
    from topomatch.stages.registration.transform3d import RigidTransform3D

    case = make_case(small_t1, 4, seed=8, multimodal=False, crop=False)
    out = topomatch.register(case.fixed, case.moving, metric="mi", seed=3)
    assert isinstance(out, topomatch.VolumeRegistrationOutcome) and out.dimension == 3 and out.metric == "mi"
    assert mean_tre(case.truth, RigidTransform3D(out.parameters, out.center), case.fixed) < 1.0
    np.testing.assert_allclose(np.asarray(out.matrix), out.registration.transform.matrix4(), atol=1e-8)
    with pytest.raises(topomatch.InputError, match="both volumes as files or both as Volume objects"):
        topomatch.register(case.fixed, ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz")



def test_a_level_whose_steps_run_out_runs_again_until_it_settles(small_t1):
    """A misalignment (rotations up to 15 degrees) longer than one run of a level's decaying steps can travel: with
    ``settle``/``reruns`` the level runs again from its end and gets closer to the known transform."""
    from topomatch.stages.registration.misalign3d import make_case, mean_tre
    from topomatch.stages.registration.register3d import Register3DParams, register_volumes

    case = make_case(small_t1, 0, seed=11, multimodal=False, crop=False)
    level = {"spacing": 4.0, "bins": 24, "iterations": 20, "step": 1.0, "c": 1.0, "samples": 4000}

    def run(**extra):
        params = Register3DParams(schedule=[{**level, **extra}], start={"steps": 0}, check={"search": False})
        reg = register_volumes(case.fixed, case.moving, params)
        return mean_tre(case.truth, reg.transform, case.fixed), reg.iterations

    once, n_once = run()
    settled, n_settled = run(settle=0.2, reruns=8)
    assert n_once == 20 and n_settled > 20
    assert once > 1.0  # the steps alone cannot travel the misalignment ...
    assert settled < 0.5 * once, (once, settled)  # ... running again until settled can


@pytest.mark.parametrize("index,multimodal,crop", [(2, False, True), (21, True, False)])
def test_small_field_of_view_low_overlap_basins_are_avoided_or_flagged(index, multimodal, crop):
    """nibabel's anatomical.nii (66 x 82 x 50 mm) moved by up to 15 degrees and 15 mm: two cases (seed 3 of the
    benchmark) that once ended, unflagged, 42 and 59 mm away in a sliver of overlap whose coarse measure beat the
    aligned position's. Either the known transform is recovered or the result is flagged; never a silent wrong
    answer."""
    from topomatch.pipeline.paths import data_root
    from topomatch.stages.registration.misalign3d import make_case, mean_tre
    from topomatch.stages.registration.register3d import register_volumes
    from topomatch.stages.registration.volume_io import read_volume

    root = data_root()
    path = None if root is None else root / "images" / "nibabel_testdata" / "anatomical.nii"
    if path is None or not path.exists():
        pytest.skip("needs nibabel's anatomical.nii in the external data root (TOPOMATCH_DATA_ROOT)")
    case = make_case(read_volume(path), index, seed=3, multimodal=multimodal, crop=crop)
    reg = register_volumes(case.fixed, case.moving)
    tre = mean_tre(case.truth, reg.transform, case.fixed)
    assert tre <= 1.0 or not reg.ok, (tre, reg.reason)
