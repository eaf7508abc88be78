"""Registration end to end, 2D and 3D: known transforms recovered, ITK cases, determinism, defaults per dimension."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from tests_paths import ITK_DIR
from topomatch.pipeline.errors import ConfigError, StageError
from topomatch.stages.registration.evaluate import evaluate_registration
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.misalign import make_case, moved
from topomatch.stages.registration.params import DIMENSION_DEFAULTS, RegisterParams, for_dimension
from topomatch.stages.registration.register import register
from topomatch.stages.registration.transform import RigidTransform


def _moved(image, tx, ty, angle):
    return moved(image, RigidTransform.euler2d(tx, ty, angle, image.center))


def _truth(tx, ty, angle):
    return {"tx": tx, "ty": ty, "angle": angle}


@pytest.fixture(scope="module")
def small_t1():
    """The bundled KmeansTest T1 volume (128 x 128 x 62 voxels of 2 x 2 x 3 mm) block-averaged to 4 x 4 x 3 mm."""
    return read_image(ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz").shrink((2, 2, 1))


@pytest.mark.parametrize("theta", [(5, 5, 5), (10, 20, 20)])
def test_thesis_misalignments_recovered(pd_slice, theta):
    reg = register(pd_slice, _moved(pd_slice, *theta))
    ev = evaluate_registration(pd_slice, reg, _truth(*theta))
    assert reg.ok, reg.reason
    assert ev.tre_mean < 0.2, (reg.transform, ev)


def test_multimodal_misalignment_recovered(pd_slice, t1_slice):
    theta = (-12.0, 8.0, -17.0)
    reg = register(t1_slice, _moved(pd_slice, *theta), RegisterParams(metric="mi"))
    assert evaluate_registration(t1_slice, reg, _truth(*theta)).tre_mean < 0.3


def _itk_cases():
    with open(ITK_DIR / "registration_pairs.csv", newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["consensus_tx"]]
    return {r["moving"] + "|" + r["fixed"]: r for r in rows}


@pytest.mark.parametrize("key", [
    "BrainProtonDensitySliceShifted13x17y.png|BrainProtonDensitySliceBorder20.png",
    "BrainProtonDensitySliceShifted13x17y.png|BrainT1SliceBorder20.png",
    "BrainProtonDensitySliceR10X13Y17.png|BrainProtonDensitySliceBorder20.png",
    "BrainProtonDensitySlice.png|BrainT1Slice.png",
])
def test_itk_cases_within_a_tenth_of_a_pixel(key):
    r = _itk_cases()[key]
    fixed, moving = read_image(ITK_DIR / r["fixed"]), read_image(ITK_DIR / r["moving"])
    truth = _truth(float(r["consensus_tx"]), float(r["consensus_ty"]), float(r["consensus_rotation_deg"]))
    reg = register(fixed, moving)
    ev = evaluate_registration(fixed, reg, truth)
    assert reg.ok and ev.tre_mean <= 0.1, (key, reg.transform, ev.tre_mean)


def test_itk_rotated10_is_the_rotation_about_itks_physical_centre():
    """The CSV's Rotated10 row, (0.094, -0.079, 10) about ((W-1)/2, (H-1)/2), is 10 degrees about ITK's
    physical centre (W/2, H/2): (I - R(10 deg)) (0.5, 0.5) = (0.094, -0.079)."""
    r = next(r for r in _itk_cases().values() if r["moving"] == "BrainProtonDensitySliceRotated10.png")
    c, s_ = math.cos(math.radians(10)), math.sin(math.radians(10))
    expected = (0.5 - (c * 0.5 - s_ * 0.5), 0.5 - (s_ * 0.5 + c * 0.5))
    assert (float(r["consensus_tx"]), float(r["consensus_ty"])) == pytest.approx(expected, abs=5e-4)


def test_anisotropic_pixels_register_in_physical_units(pd_slice):
    """The same slice with 0.8 x 1.5 mm pixels, moved by a rigid transform in mm: recovered in mm (a registration
    in pixels would see a shear)."""
    fixed = Image(pd_slice.shrink((1, 2)).data, spacing=(0.8, 1.5), name="aniso")
    truth = RigidTransform.euler2d(4.0, -6.0, 12.0, fixed.center)
    reg = register(fixed, moved(fixed, truth))
    ev = evaluate_registration(fixed, reg, _truth(4.0, -6.0, 12.0))
    assert reg.ok and ev.tre_mean < 0.3, (reg.transform, ev)


@pytest.mark.parametrize("index,multimodal,crop", [(0, False, False), (1, True, True)])
def test_3d_known_transform_recovered(small_t1, index, multimodal, crop):
    case = make_case(small_t1, index, seed=11, multimodal=multimodal, crop=crop)
    reg = register(case.fixed, case.moving)
    ev = evaluate_registration(case.fixed, reg, dict(zip(case.truth.names, (*case.truth.angles_deg,
                                                                          *case.truth.translation))))
    assert ev.tre_mean < 1.0 and reg.ok, (ev.tre_mean, reg.reason)
    assert reg.transform.center == tuple(case.fixed.center) and reg.transform.dim == 3


@pytest.mark.parametrize("d", [2, 3])
def test_same_seed_same_result(pd_slice, small_t1, d):
    if d == 2:
        fixed, moving = pd_slice, _moved(pd_slice, 4, -6, 9)
    else:
        case = make_case(small_t1, 2, seed=5, multimodal=False, crop=False)
        fixed, moving = case.fixed, case.moving
    a, b, c = (register(fixed, moving, RegisterParams(seed=s, check={"search": False})) for s in (3, 3, 4))
    np.testing.assert_array_equal(a.transform.parameters, b.transform.parameters)
    np.testing.assert_array_equal(a.history["theta"], b.history["theta"])
    assert a.transform.parameters != c.transform.parameters


@pytest.mark.parametrize("d", [2, 3])
def test_the_prefetched_self_check_work_changes_nothing(pd_slice, small_t1, monkeypatch, d):
    """With a second CPU the coarse search (and in 3D the mirror test's) runs in a thread while the levels run:
    parameters, flags, measures, history and evaluation counts equal those of the run without it."""
    from concurrent.futures import Future

    import topomatch.stages.registration.register as module

    fixed, moving = (pd_slice, _moved(pd_slice, 4, -6, 9)) if d == 2 else (small_t1, moved(small_t1, RigidTransform(
        (0.05, -0.03, 0.08, 3.0, -2.0, 1.5), small_t1.center)))
    started = []
    monkeypatch.setattr(module._Run, "prefetch", lambda run, pool, real=module._Run.prefetch: (
        real(run, pool), started.append(all(isinstance(run._grids.get(m), Future) for m in (False, d == 3)))))
    runs = []
    for threads in (2, 1):
        monkeypatch.setattr(module, "histogram_threads", lambda: threads)
        runs.append(register(fixed, moving))
    a, b = runs
    assert started == [True, False] and a.ok and a.measures == b.measures and (a.flags, a.evaluations) == (b.flags, b.evaluations)
    assert a.transform.parameters == b.transform.parameters and a.value == b.value
    np.testing.assert_array_equal(a.history["theta"], b.history["theta"])


def test_nothing_is_prefetched_for_images_that_do_not_overlap_at_the_start(small_t1, monkeypatch):
    """The coarse search's canvas spans the gap between the images: for a 4-voxel volume 500 mm away it would take
    gigabytes, and the self-check stops (no overlap) before it asks for the search; an overlapping pair gets it, and
    the mirror test's (45th round)."""
    import types

    import topomatch.stages.registration.register as module

    monkeypatch.setattr(module, "histogram_threads", lambda: 2)
    tiny = Image(np.random.default_rng(0).normal(size=(4, 4, 4)), origin=tuple(np.asarray(small_t1.center) + 500.0))
    for moving, expected in ((tiny, 0), (moved(small_t1, RigidTransform((0.0,) * 3 + (2.0,) * 3, small_t1.center)), 1)):
        params = for_dimension(RegisterParams(transform={"init": "geometry"}, start={"steps": 0}), 3)
        run = module._Run(small_t1, moving, params, module.sample_mask(small_t1, params), None)
        submitted = []
        run.prefetch(types.SimpleNamespace(submit=lambda f, *args: submitted.append((f, *args))))
        assert submitted == [(run.coarse_search,), (run.coarse_search, True)] * expected  # its own and the mirror test's


def test_the_result_is_averaged_over_other_samples_of_the_finest_level(pd_slice, monkeypatch):
    """Thirty-first round (``optimizer.ensemble``, 2D default 2, 3D 0): the result is the mean of the finest end and
    the ends of re-runs from it on other samples, leaving out an end over one unit away; a pair measured as an outline
    keeps its end. The re-runs' ends are set by hand here, so the mean is known."""
    import types

    import topomatch.stages.registration.register as module

    assert [for_dimension(RegisterParams(), d).optimizer.ensemble for d in (2, 3)] == [2, 0]
    params = for_dimension(RegisterParams(optimizer={"ensemble": 3}), 2)
    run = module._Run(pd_slice, _moved(pd_slice, 4, -6, 9), params, module.sample_mask(pd_slice, params), None)
    theta = np.array([0.1, 4.0, -6.0])
    ends = iter([theta + [0, 0.3, 0], theta + [0, -0.6, 0.3], theta + [0, 2.0, 0]])  # the last 2 units away: left out
    seeds = []
    monkeypatch.setattr(run, "histogram", lambda spec, images, samples, seed: seeds.append(seed) or run.levels[-1].objective.histogram)
    monkeypatch.setattr(run, "optimize", lambda *a, **k: types.SimpleNamespace(theta=next(ends)))
    np.testing.assert_allclose(run.ensemble(theta), theta + [0, -0.1, 0.1], atol=1e-12)
    assert len(set(seeds)) == 3 and params.seed + 2 not in seeds  # three other samples, none the finest level's own
    run.outline_measure = True
    np.testing.assert_array_equal(run.ensemble(theta), theta)


def test_history_levels_and_counts(pd_slice):
    seen = []
    reg = register(pd_slice, _moved(pd_slice, 2, 3, 4), callback=lambda level, k, theta, value: seen.append(level))
    h = reg.history
    assert len(h["level"]) == reg.iterations == len(seen) == 260 + 40 + 30
    assert h["theta"].shape == (reg.iterations, 3) and sorted(set(h["level"])) == [0, 1, 2]
    assert reg.evaluations > 2 * reg.iterations and reg.seconds > 0 and reg.stop_reason == "max_iterations"
    assert reg.summary()["method"] == "spsa/jt(alpha=2 histogram)"
    assert set(("angle", "tx", "ty", "ok", "flags", "overlap")) <= set(reg.summary())


def test_powell_deterministic(pd_slice):
    moving = _moved(pd_slice, 5, 10, 15)
    a = register(pd_slice, moving, RegisterParams(optimizer="powell"))
    b = register(pd_slice, moving, RegisterParams(optimizer="powell"))
    assert a.transform.parameters == b.transform.parameters
    assert evaluate_registration(pd_slice, a, _truth(5, 10, 15)).tre_mean < 0.1


def test_outside_the_capture_range_is_flagged(pd_slice):
    moving = _moved(pd_slice, 0, 0, 120)
    reg = register(pd_slice, moving)
    assert not reg.ok and "capture" in [f.check for f in reg.flags] or "bounds" in [f.check for f in reg.flags]
    with pytest.raises(StageError, match="registration failed: "):
        register(pd_slice, moving, RegisterParams(check={"on_failure": "error"}))


def test_estimate_on_the_search_bound_is_flagged(pd_slice):
    params = RegisterParams(bounds={"max_translation": 6}, transform={"init": "geometry"}, check={"search": False})
    reg = register(pd_slice, _moved(pd_slice, 18, 0, 0), params)
    assert not reg.ok and "search bound of tx" in reg.reason and reg.flags[0].check == "bounds"


def test_retry_from_a_probe_extends_the_capture_range(pd_slice):
    """A 45-degree misalignment: the first pass may stop short, the capture check finds the probe and retries."""
    reg = register(pd_slice, _moved(pd_slice, 3.0, -4.0, 45.0))
    assert reg.ok and evaluate_registration(pd_slice, reg, _truth(3.0, -4.0, 45.0)).tre_mean < 0.3


def test_levels_with_too_few_samples_are_measured_on_a_finer_grid_smoothed(blob_image):
    """A 64 x 80 image at 16 px per pixel would keep 20 samples: that level is measured on the native grid,
    smoothed, and the known transform is still recovered."""
    schedule = [{"spacing": 16.0, "iterations": 60, "step": 2.0, "c": 2.0, "interpolation": "linear"},
                {"spacing": 0.0, "iterations": 200, "step": 0.5, "c": 0.5}]
    reg = register(blob_image, _moved(blob_image, 2.0, -1.5, 6.0), RegisterParams(schedule=schedule))
    assert evaluate_registration(blob_image, reg, _truth(2.0, -1.5, 6.0)).tre_mean < 0.3
    assert set(reg.history["level"]) == {0, 1}


def test_dimension_defaults_apply_under_what_the_caller_set():
    two, three = for_dimension(RegisterParams(), 2), for_dimension(RegisterParams(), 3)
    assert [lv.spacing for lv in two.schedule] == [4.0, 2.0, 0.0] and three.schedule[-1].spacing == 2.0
    assert two.start.steps == 0 and three.start.steps == 2 and three.check.chance == 3.0 and two.check.chance == 0
    given = for_dimension(RegisterParams.model_validate({"bounds": {"max_angle": 30.0}, "check": {"retry": False}}), 3)
    assert given.bounds.max_angle == 30.0  # the caller's value wins
    assert given.check.retry is False and given.check.chance == DIMENSION_DEFAULTS[3]["check"]["chance"]
    custom = for_dimension(RegisterParams(schedule=[{"spacing": 1.0}]), 3)
    assert [lv.spacing for lv in custom.schedule] == [1.0]


def test_inputs_are_checked(pd_slice, small_t1):
    with pytest.raises(StageError, match="2D fixed image"):
        register(pd_slice, small_t1)
    with pytest.raises(StageError, match="mask"):
        register(pd_slice, pd_slice, fixed_mask=np.zeros(pd_slice.shape, bool))
    for bad in (np.full(pd_slice.shape, np.nan), np.full(pd_slice.shape, "no")):  # each once read as all True
        with pytest.raises(StageError, match="must be finite numbers or bools, non-zero on pixels"):
            register(pd_slice, pd_slice, fixed_mask=bad)


def test_a_mask_of_0_and_255_and_params_as_a_dict_are_accepted(pd_slice):
    """A mask as image files store it (0 / 255) selects its non-zero pixels; ``params`` as a dict of the fields is
    validated as RegisterParams (it raised AttributeError: 'dict' object has no attribute 'model_dump')."""
    mask = np.zeros(pd_slice.shape, np.uint8)
    mask[40:180, 30:150] = 255
    as_bool = register(pd_slice, pd_slice, {"seed": 3}, fixed_mask=mask > 0)
    as_bytes = register(pd_slice, pd_slice, RegisterParams(seed=3), fixed_mask=mask)
    assert as_bytes.transform.parameters == as_bool.transform.parameters and as_bytes.ok


def test_params_are_validated():
    with pytest.raises(ConfigError, match=r"register.metric.name: Input should be 'jt', 'jr', 'mi' or 'tmi'"):
        RegisterParams.parse({"metric": "nmi"}, "register")
    with pytest.raises(ConfigError, match=r"register.schedule\[0\].bins: Input should be greater than or equal to 2"):
        RegisterParams.parse({"schedule": [{"bins": 1}]}, "register")
    with pytest.raises(ConfigError, match="register.metric.alpha: Input should be greater than 0"):
        RegisterParams.parse({"metric": {"alpha": 0}}, "register")
    with pytest.raises(ConfigError, match="register.sampling.region"):
        RegisterParams.parse({"sampling": {"region": "brain"}}, "register")


@pytest.mark.parametrize("d", [2, 3])
def test_initial_translations_map_the_reference_points(d):
    from topomatch.stages.registration.register import initial_translation
    from topomatch.stages.registration.transform import euler_matrix

    shape = (20, 30) if d == 2 else (12, 14, 16)
    data = np.zeros(shape)
    data[tuple(slice(2, 6) for _ in range(d))] = 10.0
    fixed = Image(data, spacing=(1.0, 2.0, 1.5)[:d], origin=(3.0, -1.0, 2.0)[:d])
    moving = Image(np.roll(data, 3, axis=0), spacing=(0.5, 1.0, 1.0)[:d], origin=(-7.0, 4.0, 0.0)[:d])
    k = 1 if d == 2 else 3
    angles = np.full(k, 0.3)
    t = initial_translation(fixed, moving, "moments", angles)
    R, c = euler_matrix(angles), fixed.center
    np.testing.assert_allclose(R @ (fixed.centroid() - c) + c + t, moving.centroid(), atol=1e-9)
    np.testing.assert_allclose(initial_translation(fixed, moving, "geometry"), moving.center - fixed.center)


def test_sample_mask_grows_the_foreground_by_the_margin():
    from topomatch.stages.registration.params import for_dimension
    from topomatch.stages.registration.register import sample_mask

    data = np.zeros((30, 40))
    data[10:20, 15:25] = 100.0
    image = Image(data, spacing=(2.0, 2.0))
    assert sample_mask(image, for_dimension(RegisterParams(sampling={"region": "all"}), 2)) is None
    grown = sample_mask(image, for_dimension(RegisterParams(sampling={"region": "foreground", "margin": 4.0}), 2))
    assert grown.sum() == (10 + 4) * (10 + 4)  # two pixels of 2 mm on every side


def test_objective_is_undefined_below_the_overlap_and_weighted_above():
    from topomatch.stages.registration.histogram import Binning, JointHistogram
    from topomatch.stages.registration.objective import Objective

    image = Image(np.add.outer(np.arange(20.0), np.arange(30.0)) % 7)
    b = Binning.of(image.data, 8)
    jh = JointHistogram(image, image, b, b, center=image.center, mode="linear")
    plain = Objective(jh, "mi", min_overlap=0.5)
    weighted = Objective(jh, "mi", min_overlap=0.5, overlap_power=1.0)
    shift = np.array([0.0, 10.0, 0.0])  # a third of the columns leave the moving grid
    assert jh.overlap(shift) == pytest.approx(20 / 30)
    assert weighted(shift) == pytest.approx(plain(shift) * 20 / 30)
    assert plain(np.array([0.0, 20.0, 0.0])) == -math.inf  # a third of the samples is below min_overlap


def test_before_after_of_the_identity_is_the_moving_image():
    from topomatch.stages.registration.reports import before_after, planes
    from topomatch.stages.registration.transform import RigidTransform

    vol = Image(np.random.default_rng(0).random((6, 7, 8)), spacing=(1.0, 2.0, 3.0))
    identity = RigidTransform.identity(tuple(vol.center))
    before, after = before_after(vol, vol, identity)
    np.testing.assert_allclose(before, vol.data, atol=1e-12)
    np.testing.assert_allclose(after, vol.data, atol=1e-12)
    views = planes(vol)
    assert [v[1].shape for v in views] == [(7, 8), (6, 8), (6, 7)] and views[1][2] == pytest.approx(3.0)
    assert len(planes(Image(np.zeros((5, 6))))) == 1


def test_a_small_field_is_registered_in_working_units(pd_slice):
    """The PD slice at 0.1 and 0.2 mm pixels (18 x 22 and 36 x 43 mm, smaller than SMALL_FIELD: a small-animal
    scale), moved by 10 deg and (13, 17) pixels: recovered within a pixel, in working units of the largest extent
    over SMALL_FIELD (``measures['unit']``), so that the two answers are one answer at two scales. Registered in
    millimetres, the defaults' steps (up to 4 mm) throw a 20 mm field about (the sources attack's ``mr-small``)."""
    from topomatch.stages.registration.register import SMALL_FIELD

    results = []
    for spacing in (0.1, 0.2):
        fixed = Image(pd_slice.data, (spacing, spacing), name="pd-small")
        truth = RigidTransform.euler2d(13 * spacing, 17 * spacing, 10.0, fixed.center)
        reg = register(fixed, moved(fixed, truth))
        ev = evaluate_registration(fixed, reg, _truth(13 * spacing, 17 * spacing, 10.0))
        assert reg.ok and ev.tre_mean < spacing, (spacing, ev.tre_mean, reg.reason)
        assert reg.measures["unit"] == pytest.approx(217 * spacing / SMALL_FIELD)
        seen = []
        again = register(fixed, moved(fixed, truth), callback=lambda level, k, theta, value: seen.append(theta))
        np.testing.assert_allclose(seen, reg.history["theta"])  # physical units, as the history
        assert again.transform == reg.transform
        results.append(reg.transform)
    small, large = results
    assert small.angles_deg[0] == pytest.approx(large.angles_deg[0], abs=0.05)
    np.testing.assert_allclose(2 * small.translation, large.translation, atol=0.01)


@pytest.mark.parametrize("spacing", [50.0, 100.0])
def test_a_large_field_is_registered_in_working_units(pd_slice, spacing):
    """The bundled PD pair (10 deg, (13, 17) pixels) with its pixels relabelled 50 and 100 mm (11 and 22 m fields,
    larger than LARGE_FIELD): one answer in pixels whatever the scale, the 1 mm one within 0.05 px, ok, in working
    units of the largest extent over LARGE_FIELD. Registered in millimetres (before the twenty-seventh round) the
    rotation drifted (3.8 deg at 50 mm) and the result was flagged by ``agreement``."""
    from topomatch.stages.registration.register import LARGE_FIELD

    moving = read_image(ITK_DIR / "BrainProtonDensitySliceR10X13Y17.png")
    unit = register(pd_slice, moving)
    big = register(Image(pd_slice.data, (spacing, spacing)), Image(moving.data, (spacing, spacing)))
    assert big.ok and big.measures["unit"] == pytest.approx(217 * spacing / LARGE_FIELD)
    assert big.transform.angles_deg[0] == pytest.approx(unit.transform.angles_deg[0], abs=0.02)
    np.testing.assert_allclose(np.asarray(big.transform.translation) / spacing, unit.transform.translation, atol=0.05)


@pytest.mark.parametrize("corner", [(60, 60), (80, 50), (100, 90)])
@pytest.mark.parametrize("angle, tx, ty", [(15.0, 1.0, -1.0), (-12.0, -2.0, 1.5)])
def test_a_20_mm_field_is_recovered(pd_slice, corner, angle, tx, ty):
    """64 x 64 windows of the PD slice at 0.3125 mm (pydicom's ``MR_small`` geometry: a 20 mm field) with 2 % noise:
    within a tenth of a pixel. Registered in millimetres (before the twenty-fifth round), (80, 50) at 15 deg and
    (100, 90) at -12 deg ended 20 and 39 pixels away, flagged."""
    s, (r, c) = 0.3125, corner
    fixed = Image(pd_slice.data[r: r + 64, c: c + 64], (s, s), name="pd-window")
    reg = register(fixed, moved(fixed, RigidTransform.euler2d(tx, ty, angle, fixed.center), noise=0.02))
    ev = evaluate_registration(fixed, reg, _truth(tx, ty, angle))
    assert reg.ok and ev.tre_mean < 0.1 * s, (ev.tre_mean / s, reg.reason)


def test_a_huge_translation_bound_is_held_to_where_the_images_can_overlap(pd_slice):
    """``bounds.max_translation`` = 1e20 (a user's "no limit") is held to the two images' largest extents added: the
    coarse search stays the size it would be at that bound, and the known transform is recovered (it used to
    allocate gigabytes, then fail with an internal error)."""
    truth = RigidTransform.euler2d(4.0, -6.0, 9.0, pd_slice.center)
    reg = register(pd_slice, moved(pd_slice, truth), RegisterParams(bounds={"max_translation": 1e20}))
    ev = evaluate_registration(pd_slice, reg, _truth(4.0, -6.0, 9.0))
    assert reg.ok and ev.tre_mean < 0.3, (ev.tre_mean, reg.reason)
    with pytest.raises(ConfigError, match="finite"):
        RegisterParams.parse({"bounds": {"max_translation": math.inf}}, "register")
