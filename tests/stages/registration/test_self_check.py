"""The self-check is right both ways, 2D and 3D: correct results pass, wrong ones are flagged.

Cases: self-registration (the answer is the identity), small images (33 x 41 px, the size of nibabel's
``anatomical.nii`` slices), moving images shifted until too little of them is left, unrelated images, a
straight edge, volumes without overlap or shared content; and the coarse search's own pieces (scores, flatness).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests_paths import ITK_DIR
from topomatch.stages.registration.divergence import jensen_tsallis_histogram
from topomatch.stages.registration.evaluate import tre_points
from topomatch.stages.registration.image import Image, foreground_mask
from topomatch.stages.registration.io import read_image
from topomatch.stages.registration.misalign import make_case, moved
from topomatch.stages.registration.params import RegisterParams
from topomatch.stages.registration.register import register
from topomatch.stages.registration.search import (GridSearch, SearchImages, batch_jensen_tsallis2, directions, flatness,
                                                  grid_search, search_spacing)
from topomatch.stages.registration.structure import object_mask
from topomatch.stages.registration.transform import RigidTransform, target_registration_error

ANATOMICAL = "images/nibabel_testdata/anatomical.nii"


def _moved(image, tx, ty, angle):
    return moved(image, RigidTransform.euler2d(tx, ty, angle, image.center))


def _tre(fixed: Image, reg, truth: RigidTransform) -> float:
    return float(np.mean(target_registration_error(reg.transform, truth.with_center(fixed.center),
                                                   tre_points(fixed))))


def _small(image: Image, factor: int) -> Image:
    return Image(image.shrink((factor, factor)).data, name=f"{image.name}_small")  # small, in pixel units


@pytest.fixture(scope="module")
def small_t1():
    return read_image(ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz").shrink((2, 2, 1))


def test_batch_jensen_tsallis_matches_the_histogram_formula():
    rng = np.random.default_rng(3)
    h = rng.integers(0, 20, size=(5, 16, 16)).astype(float)
    h[2, 3] = 0  # an empty row
    expected = [jensen_tsallis_histogram(x, 2.0, "histogram") for x in h]
    np.testing.assert_allclose(batch_jensen_tsallis2(h), expected, rtol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_grid_scores_equal_single_scores(pd_slice, small_t1, d):
    fixed = pd_slice if d == 2 else small_t1
    moving = moved(fixed, RigidTransform(((0.3,) if d == 2 else (0.1, 0.0, 0.2)) + (12.0, -7.0, 3.0)[:d],
                                         tuple(fixed.center)))
    images = SearchImages(fixed, moving, center=fixed.center, min_overlap=0.25)
    rotations = np.radians([[0.0], [45.0], [90.0]]) if d == 2 else np.radians([[0, 0, 0], [30, 0, 0]])
    grid = grid_search(images, rotations, lambda a: np.full(d, 3.0), steps=5, half_width=40.0)
    assert grid.n_coarse == len(rotations) * 5 ** d
    for i in range(0, len(grid.thetas), 37):
        assert grid.values[i] == pytest.approx(images.score(grid.thetas[i]), rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("d", [2, 3])
def test_search_with_a_region_ignores_an_empty_margin_of_the_fixed_grid(pd_slice, small_t1, d):
    """Thirty-ninth round: with the sampling region, the search copy is scaled to the region and samples only it, so
    background added around the fixed grid (whole search blocks, the same physical placement) changes no score; without
    it the copy is scaled to the grid and the scores move."""
    fixed = pd_slice if d == 2 else small_t1
    moving = moved(fixed, RigidTransform(((0.3,) if d == 2 else (0.1, 0.0, 0.2)) + (12.0, -7.0, 3.0)[:d],
                                         tuple(fixed.center)))
    region = foreground_mask(fixed)
    factor = [max(1, int(search_spacing([fixed, moving], region) // s)) for s in fixed.spacing]  # ITK order
    whole = [(0, -n % f) for n, f in zip(fixed.shape, factor[::-1])]  # the grid in whole blocks (none dropped)
    fixed, region = fixed.with_data(np.pad(fixed.data, whole, constant_values=fixed.data.min())), np.pad(region, whole)
    pad = [(3 * f, 5 * f) for f in factor[::-1]]  # array order, whole blocks on the low side
    low = np.array([p[0] for p in pad])[::-1] * np.asarray(fixed.spacing)
    padded = Image(np.pad(fixed.data, pad, constant_values=fixed.data.min()), fixed.spacing,
                   tuple(np.asarray(fixed.origin) - fixed.direction @ low), fixed.direction)
    rotations = np.radians([[0.0], [45.0]]) if d == 2 else np.radians([[0, 0, 0], [30, 0, 0]])
    grids = [grid_search(SearchImages(f, moving, center=fixed.center, min_overlap=0.25, region=r), rotations,
                         lambda a: np.full(d, 3.0), steps=5, half_width=40.0)
             for f, r in ((fixed, region), (padded, np.pad(region, pad)), (fixed, None), (padded, None))]
    n = grids[0].n_coarse  # the regular grid (the polished points follow the best cells, ties in any order)
    np.testing.assert_array_equal(grids[0].thetas[:n], grids[1].thetas[:n])
    np.testing.assert_allclose(grids[0].raw[:n], grids[1].raw[:n], rtol=1e-12, atol=1e-15)
    assert not np.allclose(grids[2].raw[:n], grids[3].raw[:n], equal_nan=True)


def test_directions_cover_every_axis_pair_once():
    assert len(directions(3)) == 13  # axes, face and body diagonals, one of each opposite pair
    assert len(directions(6)) == 6 + 4 * 15 // 2  # axes and pair diagonals
    np.testing.assert_allclose(np.linalg.norm(directions(6), axis=1), 1.0)


@pytest.mark.parametrize("d", [2, 3])
def test_flatness_of_a_quadratic_is_its_drop_ratio(d):
    """On an exact quadratic ``-(u' A u)`` of the unit (arc, translation) vector u, with A diagonal, the drop along
    an axis is its eigenvalue: the ratio is the smallest over the largest, the flattest direction its axis."""
    p, radius = (3, 6)[d - 2], 50.0
    eigen = np.linspace(0.1, 2.0, p)[::-1]  # the last axis (a translation) is the flattest
    unit = np.r_[[radius] * (p - d), [1.0] * d]  # radians -> arc
    ratio, u = flatness(lambda t: -float(((t * unit) ** 2) @ eigen), np.zeros(p), dim=d, reach=3.0, radius=radius)
    assert ratio == pytest.approx(0.1 / 2.0)
    np.testing.assert_allclose(np.abs(u), np.eye(p)[-1])


@pytest.mark.parametrize("factor", [5, 6])
def test_small_images_register_to_themselves(pd_slice, factor):
    small = _small(pd_slice, factor)  # 43 x 36 and 36 x 30 px
    reg = register(small, small)
    assert reg.ok, reg.reason
    assert _tre(small, reg, RigidTransform.identity(tuple(small.center))) < 0.1


@pytest.mark.parametrize("theta", [(2.5, -1.5, 8.0), (-3.0, 2.0, -12.0)])
def test_small_images_recover_a_known_transform(pd_slice, theta):
    small = _small(pd_slice, 5)
    reg = register(small, _moved(small, *theta))
    assert reg.ok, reg.reason
    assert _tre(small, reg, RigidTransform.euler2d(*theta, small.center)) < 0.6


def test_every_anatomical_slice_registers_to_itself():
    from topomatch.pipeline.paths import data_root

    root = data_root()
    if root is None or not (root / ANATOMICAL).exists():
        pytest.skip("needs nibabel's anatomical.nii in the external data root (TOPOMATCH_DATA_ROOT)")
    for index in range(25):
        image = read_image(root / ANATOMICAL, slice_index=index)
        reg = register(image, image)
        identity = RigidTransform.identity(tuple(image.center))
        assert reg.ok and _tre(image, reg, identity) < 0.1, (index, reg.transform, reg.reason)


@pytest.mark.parametrize("theta", [(6.0, -4.0, 8.0), (-9.0, 5.0, -15.0)])
def test_an_inverted_moving_image_registers_ok(pd_slice, theta):
    """A negative of the fixed image (dark head on a bright background) shares all its content: found and ok."""
    moving = _moved(pd_slice, *theta)
    moving = Image(moving.data.max() - moving.data, name="inverted")
    reg = register(pd_slice, moving)
    assert reg.ok, reg.reason
    assert _tre(pd_slice, reg, RigidTransform.euler2d(*theta, pd_slice.center)) < 0.5


@pytest.mark.parametrize("theta", [(150.0, 45.0, 0.0), (170.0, 51.0, 30.0)])
def test_a_moving_image_shifted_out_of_view_is_flagged(pd_slice, theta):
    reg = register(pd_slice, _moved(pd_slice, *theta))
    assert not reg.ok
    assert {"content", "overlap", "overlap_bound"} & {f.check for f in reg.flags}, reg.reason


@pytest.mark.parametrize("theta", [(90.0, 27.0, 0.0), (120.0, 36.0, 30.0)])
def test_large_shifts_are_found_by_the_coarse_search(pd_slice, theta):
    reg = register(pd_slice, _moved(pd_slice, *theta))
    assert reg.ok, reg.reason
    assert _tre(pd_slice, reg, RigidTransform.euler2d(*theta, pd_slice.center)) < 0.5


def test_a_result_pressed_against_the_overlap_bound_is_flagged(pd_slice):
    theta = (84.0, -112.0, -40.0)  # 23 % of the fixed image overlaps the moving one at the truth
    reg = register(pd_slice, _moved(pd_slice, *theta))
    assert _tre(pd_slice, reg, RigidTransform.euler2d(*theta, pd_slice.center)) > 1.0 and not reg.ok, reg.summary()


def test_noise_is_not_registered(pd_slice):
    noise = pd_slice.with_data(np.random.default_rng(0).normal(100.0, 50.0, size=pd_slice.shape), name="noise")
    reg = register(pd_slice, noise)
    assert not reg.ok and "prominence" in {f.check for f in reg.flags}


def test_an_edge_is_flagged_as_undetermined_not_ok(pd_slice):
    """A straight edge moved along and across itself: translation along it is not determined, and the self-check
    says so (the measure is flat along it, or the finest level wandered from the coarse answer, or, the edge
    image being an outline-only pair, its outline cannot be compared) instead of returning an arbitrary point of
    the valley."""
    H, W = pd_slice.shape
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    edge = pd_slice.with_data(200.0 * (xx + yy < H) + np.random.default_rng(1).normal(0, 3, (H, W)), name="edge")
    reg = register(edge, _moved(edge, 5.0, 7.0, 0.0))
    assert not reg.ok and {"flatness", "consistency", "outline"} & {f.check for f in reg.flags}, reg.reason


def test_3d_no_overlap_after_initialisation_is_flagged(small_t1):
    tiny = Image(np.random.default_rng(0).normal(size=(4, 4, 4)), origin=tuple(np.asarray(small_t1.center) + 500.0))
    reg = register(small_t1, tiny, RegisterParams(transform={"init": "geometry"}, start={"steps": 0}))
    assert not reg.ok and "overlap" in reg.reason


@pytest.mark.parametrize("seed", [1, 2])
def test_3d_unrelated_content_is_flagged(small_t1, seed):
    """Noise against a head: the measure at any result stays at its chance level (the samples paired at random),
    whatever optimum the optimiser settles in."""
    noise = small_t1.with_data(np.random.default_rng(seed).normal(size=small_t1.shape))
    reg = register(small_t1, noise)
    assert not reg.ok and "chance level" in reg.reason, reg.summary()


def test_a_3d_result_that_does_not_stand_out_of_the_coarse_search_is_flagged_only(small_t1, monkeypatch):
    """Fifteenth round: the prominence test flags in 3D too, at 2D's threshold, on pairs that are not outline-only. A
    known transform is recovered; with the coarse search's landscape made to rank the result 3 MADs above its median
    (below ``min_prominence``, above 0: the value that never flagged in 3D before), the same transform comes back,
    flagged; the same moving image as a silhouette (an outline-only pair) is not judged by it in 3D."""
    truth = RigidTransform((0.05, -0.03, 0.08, 3.0, -2.0, 1.5), small_t1.center)
    moving = moved(small_t1, truth)
    plain = register(small_t1, moving)
    assert plain.ok and plain.measures["prominence"] >= RegisterParams().check.min_prominence, plain.summary()
    monkeypatch.setattr(GridSearch, "prominence", lambda self, value: 3.0)
    flagged = register(small_t1, moving)
    assert [f.check for f in flagged.flags] == ["prominence"] and flagged.measures["prominence"] == 3.0
    np.testing.assert_array_equal(flagged.transform.parameters, plain.transform.parameters)
    assert _tre(small_t1, flagged, truth) < 0.5
    silhouette = moving.with_data(np.where(object_mask(moving), 100.0, 0.0)
                                  + np.random.default_rng(0).normal(0.0, 2.0, moving.shape))
    outline = register(small_t1, silhouette)  # an outline-only pair: its coarse landscape is broad, not judged in 3D
    assert outline.measures["prominence"] == 3.0 and "prominence" not in {f.check for f in outline.flags}
    assert "outline_gap" in outline.measures, outline.measures  # read as outline-only: check_outline measured it


def test_finest_level_averaging_moves_only_pairs_measured_as_images(pd_slice):
    """Seventeenth round: ``optimizer.average_finest`` (2D default 10) averages the finest level's last iterates of a
    pair measured as an image, which still recovers a known transform; an outline-only pair (a silhouette) is measured
    as an outline and its result is bit-identical whatever the option says."""
    truth = RigidTransform.euler2d(6.0, -4.0, 8.0, pd_slice.center)
    moving = moved(pd_slice, truth)
    assert RegisterParams().optimizer.average_finest == 10
    one, ten = (register(pd_slice, moving, RegisterParams(optimizer={"average_finest": n})) for n in (1, 10))
    assert not np.array_equal(one.transform.parameters, ten.transform.parameters)
    assert ten.ok and _tre(pd_slice, ten, truth) < 0.2, ten.summary()
    silhouette = moving.with_data(np.where(object_mask(moving), 100.0, 0.0)
                                  + np.random.default_rng(0).normal(0.0, 2.0, moving.shape))
    one, ten = (register(pd_slice, silhouette, RegisterParams(optimizer={"average_finest": n})) for n in (1, 10))
    assert "outline_gap" in ten.measures  # measured as an outline
    np.testing.assert_array_equal(one.transform.parameters, ten.transform.parameters)


def test_a_level_whose_steps_run_out_runs_again_until_it_settles(small_t1):
    """A misalignment longer than one run of a level's decaying steps can travel: with ``settle``/``reruns`` the
    level runs again from its end and gets closer to the known transform."""
    case = make_case(small_t1, 0, seed=11, multimodal=False, crop=False)
    level = {"spacing": 4.0, "bins": 24, "iterations": 20, "step": 1.0, "c": 1.0, "samples": 4000}

    def run(**extra):
        params = RegisterParams(schedule=[{**level, **extra}], start={"steps": 0}, check={"search": False})
        reg = register(case.fixed, case.moving, params)
        return _tre(case.fixed, reg, case.truth), reg.iterations

    once, n_once = run()
    settled, n_settled = run(settle=0.2, reruns=8)
    assert n_once == 20 and n_settled > 20
    assert once > 1.0  # the steps alone cannot travel the misalignment ...
    assert settled < 0.5 * once, (once, settled)  # ... running again until settled can


@pytest.mark.parametrize("index,multimodal,crop", [(2, False, True), (21, True, False)])
def test_small_field_of_view_low_overlap_basins_are_avoided_or_flagged(index, multimodal, crop):
    """nibabel's anatomical.nii (66 x 82 x 50 mm) moved by up to 15 degrees and 15 mm: either the known transform
    is recovered or the result is flagged; never a silent wrong answer."""
    from topomatch.pipeline.paths import data_root

    root = data_root()
    if root is None or not (root / ANATOMICAL).exists():
        pytest.skip("needs nibabel's anatomical.nii in the external data root (TOPOMATCH_DATA_ROOT)")
    case = make_case(read_image(root / ANATOMICAL), index, seed=3, multimodal=multimodal, crop=crop)
    reg = register(case.fixed, case.moving)
    tre = _tre(case.fixed, reg, case.truth)
    assert tre <= 1.0 or not reg.ok, (tre, reg.reason)


@pytest.mark.parametrize("d", [2, 3])
def test_shortlisted_probes_are_the_best_at_the_first_level_of_the_grids_best(pd_slice, small_t1, d):
    """``_Run.shortlisted``: the ``candidates`` best, by the first level's measure, of the ``check.shortlist`` grid
    transforms the grid's own ranking gives (a grid cell apart from the result and from each other)."""
    from topomatch.stages.registration.params import for_dimension
    from topomatch.stages.registration.register import _Run

    image = pd_slice if d == 2 else small_t1
    result = np.zeros(3 if d == 2 else 6)
    run = _Run(image, image, for_dimension(RegisterParams(check={"shortlist": 8, "candidates": 3}), d), None, None)
    longer = run.candidates(result, 8)
    assert len(longer) == 8 and all(np.array_equal(a, b) for a, b in zip(run.candidates(result), longer[:3]))
    first = run.levels[0].objective
    by_measure = sorted(longer, key=lambda t: -first(t))[:3]
    got = run.shortlisted(result)
    assert len(got) == 3 and all(np.array_equal(a, b) for a, b in zip(got, by_measure))


def test_a_basin_only_the_shortlist_finds_is_adopted(pd_slice, monkeypatch):
    """A 45-degree misalignment stops short of the truth and the grid's own probes find the true basin, which is
    adopted (``restarts`` 1). With those probes taken away, the shortlisted ones find it, and it is adopted too
    (thirty-second round; from the thirteenth it was only flagged on a pair read as an image)."""
    from topomatch.stages.registration import register as reg_module

    moving = _moved(pd_slice, 3.0, -4.0, 45.0)
    adopted = register(pd_slice, moving)
    assert adopted.ok and adopted.restarts == 1
    grid_own = reg_module._Run.candidates
    monkeypatch.setattr(reg_module._Run, "candidates",
                        lambda self, theta, n=None: [] if n is None else grid_own(self, theta, n))
    stopped = register(pd_slice, moving, RegisterParams(check={"search": False}))  # the schedule's own end
    shortlisted = register(pd_slice, moving, RegisterParams(check={"shortlist": 10}))
    assert shortlisted.ok and shortlisted.restarts == 1, shortlisted.reason
    truth = RigidTransform.euler2d(3.0, -4.0, 45.0, pd_slice.center)
    assert _tre(pd_slice, stopped, truth) > 1.0 > _tre(pd_slice, shortlisted, truth)


@pytest.mark.parametrize("d", [2, 3])
def test_a_jt_result_is_climbed_by_mutual_information_and_only_flagged(pd_slice, small_t1, d):
    """Twelfth round (``check.mi_agreement``): JT's result on a structured pair is climbed by mutual information at
    the finest level. On a known transform of the same image both measures peak at the truth: MI ends a small
    fraction of a unit away. With the limit below that distance the result is flagged ``agreement``, naming mutual
    information; the transform is the same with the test off, on, and firing (its climb has a stream of its own).
    Asked of the finest level's own end (``optimizer.ensemble: 0``): the 2D default's mean over other samples (the
    thirty-first round) is where MI does not climb at all here (distance 0, not flagged)."""
    fixed = pd_slice if d == 2 else small_t1
    truth = RigidTransform.from_degrees((10.0, 4.0, -3.0) if d == 2 else (4.0, -3.0, 6.0, 3.0, -2.0, 1.5),
                                        fixed.center)
    moving = moved(fixed, truth)
    assert register(fixed, moving).measures["agreement"] < 0.3
    default = register(fixed, moving, RegisterParams(optimizer={"ensemble": 0}))
    off = register(fixed, moving, RegisterParams(optimizer={"ensemble": 0}, check={"mi_agreement": 0}))
    assert default.ok and "agreement" not in off.measures, default.reason
    distance = default.measures["agreement"]
    assert 0 < distance < 0.3
    firing = register(fixed, moving, RegisterParams(optimizer={"ensemble": 0}, check={"mi_agreement": distance / 2}))
    assert not firing.ok and [f.check for f in firing.flags] == ["agreement"]
    assert "mutual information" in firing.reason
    for other in (off, firing):
        np.testing.assert_array_equal(other.transform.parameters, default.transform.parameters)
    assert _tre(fixed, default, truth) < 0.3


@pytest.mark.parametrize("outline", [False, True])
def test_shortlisted_probes_are_adopted_on_every_pair(pd_slice, monkeypatch, outline):
    """The capture test asks the grid's own probes (a winner adopted), then the shortlisted ones, whose winner is
    adopted on a pair measured at order 1 (here the PD slice against its own silhouette) and, since the thirty-second
    round, on a structured pair too (the slice against itself); the 3D start search's probe only flags."""
    from topomatch.stages.registration import register as reg_module
    from topomatch.stages.registration.structure import object_mask

    calls, real = [], reg_module._better_basin

    def spy(run, theta, value, probes, *, adopt):
        calls.append((adopt, run.outline_measure))
        return real(run, theta, value, probes, adopt=adopt)

    monkeypatch.setattr(reg_module, "_better_basin", spy)
    source = pd_slice.with_data(np.where(object_mask(pd_slice), 100.0, 0.0)) if outline else pd_slice
    reg = register(pd_slice, _moved(source, 3.0, -4.0, 10.0))
    start_search = [] if outline else [(False, False)]  # the twenty-second round's probe: structured pairs only
    assert reg.ok and calls == [(True, outline), (True, outline)] + start_search, (reg.reason, calls)


def test_a_basin_only_the_start_search_finds_flags_and_leaves_the_estimate_as_it_was(pd_slice, monkeypatch):
    """Twenty-second round (``check.start_search``): a 2D pair read as an image, started 78 px from the truth with
    the grid's probes taken away, ends in a wrong basin; the 3D start search's end finds the true one, which flags
    ``capture`` naming it and is not adopted: parameters, iterations and the other flags are those of the probe
    off, bit for bit (its stream and history are its own)."""
    from topomatch.stages.registration import register as reg_module

    real = reg_module._Run.start_search
    monkeypatch.setattr(reg_module._Run, "candidates", lambda self, theta, n=None: [])
    monkeypatch.setattr(reg_module._Run, "start_search", lambda self, t_init, st=None: real(self, t_init, st)
                        if st is not None else np.r_[0.0, np.asarray(t_init) + (60.0, 50.0)])
    moving = _moved(pd_slice, 8.0, -6.0, 0.0)
    off = register(pd_slice, moving, RegisterParams(check={"start_search": False}))
    on = register(pd_slice, moving)
    truth = RigidTransform.euler2d(8.0, -6.0, 0.0, pd_slice.center)
    assert _tre(pd_slice, off, truth) > 50 and "capture" not in [f.check for f in off.flags]
    on_checks = [f.check for f in on.flags]  # the probe adds capture; every other flag is the same, in order
    assert [c for c in on_checks if c != "capture"] == [f.check for f in off.flags] and "capture" in on_checks
    assert "start_search" in on.reason
    np.testing.assert_array_equal(on.transform.parameters, off.transform.parameters)
    assert on.iterations == off.iterations and on.restarts == off.restarts == 0


def test_an_optimiser_that_stops_short_of_an_optimum_is_flagged(pd_slice):
    """A schedule of absurd steps (100 units: every step overshoots and is blocked) returns its start, 10 degrees
    from the truth; one unit from it the finest measure is higher (``ascent`` > ``check.margin``): ``gain`` flags it
    (without ``check.retry``, so that the capture test's better probe is not adopted). With it, that probe (a coarse
    grid angle near the truth, kept although its refine overshoots too: thirty-eighth round) is adopted, and its
    result, which the absurd steps cannot polish either, is flagged by ``gain`` as well.
    The defaults' result on the same pair is a local optimum (every unit step lowers the measure)."""
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform

    moving = moved(pd_slice, RigidTransform.euler2d(3.0, -4.0, 10.0, pd_slice.center))
    stuck = register(pd_slice, moving, RegisterParams(schedule=[{"step": 100.0}], check={"retry": False}))
    assert abs(stuck.transform.angles_deg[0] - 10.0) > 5 and "gain" in [f.check for f in stuck.flags]
    assert stuck.measures["ascent"] > 0.005
    retried = register(pd_slice, moving, RegisterParams(schedule=[{"step": 100.0}]))
    assert retried.restarts == 1 and abs(retried.transform.angles_deg[0] - 10.0) < 2.5
    assert "gain" in [f.check for f in retried.flags] and retried.measures["ascent"] > 0.005
    good = register(pd_slice, moving)
    assert good.ok and good.measures["ascent"] < 0


def test_a_pair_smoothed_to_constants_is_flagged(pd_slice):
    """A schedule whose smoothing (1000 units) makes both images constant: the measure is 0 everywhere and the start
    comes back; ``gain`` says the images carry no information there."""
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform

    moving = moved(pd_slice, RigidTransform.euler2d(3.0, -4.0, 10.0, pd_slice.center))
    flat = register(pd_slice, moving, RegisterParams(schedule=[{"smoothing": 1000.0}]))
    assert flat.value == 0.0 and any(f.check == "gain" and "no information" in f.message for f in flat.flags)


def test_stability_flags_a_result_another_sample_moves_farther_than_its_limit(pd_slice):
    """The finest level run again on another sample of the images never ends exactly where the first did: with
    ``check.stability`` at 1e-9 units the test fires and records that distance; at 0 (the 2D default) it is off."""
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform

    moving = moved(pd_slice, RigidTransform.euler2d(3.0, -4.0, 10.0, pd_slice.center))
    strict = register(pd_slice, moving, RegisterParams(check={"stability": 1e-9}))
    assert [f.check for f in strict.flags] == ["stability"] and 0 < strict.measures["stability"] < 0.5
    assert "stability" not in register(pd_slice, moving).measures


def test_a_start_without_overlap_says_so_and_suggests_swapping(pd_slice):
    """A 32 x 32 moving patch of a 181 x 217 fixed slice: 2 % of the fixed samples overlap it at the start. The
    ``start`` flag names the overlap (not the optimiser's stop reason) and suggests the swap that works."""
    from topomatch.stages.registration.image import Image, foreground_mask
    from topomatch.stages.registration.register import register

    patch = Image(pd_slice.data[90:122, 70:102], name="patch")
    start = [f for f in register(pd_slice, patch).flags if f.check == "start"]
    assert start and "(no overlap)" in start[0].message and "swap them" in start[0].message


def test_check_angles_refuse_nan():
    from topomatch.pipeline.errors import ConfigError
    from topomatch.stages.registration.params import RegisterParams

    with pytest.raises(ConfigError, match="finite"):
        RegisterParams.parse({"check": {"angles": [float("nan")]}}, "register")


@pytest.mark.parametrize("case_id", ["capture-2d-itk-065", "capture-2d-itk-029"])
def test_a_fixed_mask_whose_grown_foreground_misses_the_basin_is_captured_by_sampling_every_pixel(case_id):
    """Two tune-side cases of the validation corpus (bundled data only): the ITK slice's head mask as the fixed image,
    the T1 with a bias field turned 18 and 13 degrees as the moving one. The default samples (the mask grown by 16
    mm) lead every level to a wrong basin, 32 and 35 px off, flagged by `capture`; the thirtieth round's probe (the
    pair sampled over every fixed pixel, adopted where the finest measure is higher) recovers the truth, ok."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[3] / "benchmarks"))
    import registration_corpus as corpus

    spec = next(s for s in corpus.plan_split("capture", 2) if s.id == case_id)
    case = corpus.build_case(spec)
    reg = register(case.fixed, case.moving)
    assert _tre(case.fixed, reg, case.truth) < 0.5 and reg.ok and reg.restarts == 1, reg.summary()
