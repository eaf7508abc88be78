"""Exact answers, in 2D and 3D, for public functions of the registration folder whose tests only checked shapes,
seeds or agreement with themselves (an audit of the folder on 2026-12-06): each value here is computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.stages.registration.evaluate import EvaluateParams, evaluate_registration, tre_points
from topomatch.stages.registration.image import Image, border, foreground_mask, gaussian_blur
from topomatch.stages.registration.misalign import crop_slab, moved
from topomatch.stages.registration.params import RegisterParams, for_dimension
from topomatch.stages.registration.register import Registration, describe, sample_mask
from topomatch.stages.registration.search import GridSearch
from topomatch.stages.registration.structure import object_mask
from topomatch.stages.registration.transform import RigidTransform, euler_angles, euler_matrix


def _registration(transform: RigidTransform) -> Registration:
    return Registration(transform, 0.0, (), "test", 0.01, 1, 2, "max_iterations")


def test_moved_by_whole_pixels_is_a_shift_filled_with_zeros():
    """``moved(source, T)(q) = source(T^-1 q)``: a translation of 2 pixels along x moves the columns right by 2 (2D),
    one of 1 voxel along z the slices by 1 (3D); linear interpolation at whole pixels is exact."""
    a = np.random.default_rng(0).random((12, 15))
    m = moved(Image(a), RigidTransform((0.0, 2.0, 0.0), (7.0, 5.5)), order=1).data
    np.testing.assert_allclose(m[:, 2:], a[:, :-2], atol=1e-12)
    assert np.all(m[:, :2] == 0.0)
    b = np.random.default_rng(1).random((6, 7, 8))
    m3 = moved(Image(b), RigidTransform((0.0,) * 3 + (0.0, 0.0, 1.0), (3.5, 3.0, 2.5)), order=1).data
    np.testing.assert_allclose(m3[1:], b[:-1], atol=1e-12)
    assert np.all(m3[0] == 0.0)


def test_crop_slab_in_2d_keeps_the_pixels_where_they_were():
    arr = np.arange(120.0).reshape(10, 12)
    out = crop_slab(Image(arr, (1.0, 1.0), (5.0, -3.0)), axis=0, fraction=0.5, start_fraction=1.0)
    np.testing.assert_array_equal(out.data, arr[:, 6:])
    assert out.origin == (11.0, -3.0)


@pytest.mark.parametrize("d", [2, 3])
def test_tre_points_are_the_regions_pixels_thinned_by_a_stride(d):
    rng = np.random.default_rng(d)
    data = np.zeros((9,) * d)
    data[(slice(2, 7),) * d] = 10.0 + rng.random((5,) * d)
    image = Image(data, (0.5,) * d, (1.0,) * d)
    region = "all" if d == 2 else "foreground"
    flat = np.arange(data.size) if d == 2 else np.flatnonzero(foreground_mask(image))
    np.testing.assert_array_equal(tre_points(image), image.points(flat))
    assert len(flat) == (81 if d == 2 else 125)  # 2D: every pixel; 3D: the 5^3 cube, its content
    stride = math.ceil(len(flat) / 10)
    np.testing.assert_array_equal(tre_points(image, region, max_points=10), image.points(flat[::stride]))


def test_evaluate_a_3d_rotation_error_by_hand():
    """2 degrees about z through the grid's centre: each point moves by the chord 2 r_xy sin(1 deg), r_xy its distance
    from the axis; every point counts (region ``all``)."""
    vol = Image(np.random.default_rng(0).random((5, 6, 7)), (1.0, 2.0, 3.0))
    est = RigidTransform((0.0, 0.0, math.radians(2.0), 0.0, 0.0, 0.0), tuple(vol.center))
    ev = evaluate_registration(vol, _registration(est), {"angle_x": 0.0, "angle_y": 0.0, "angle_z": 0.0},
                               EvaluateParams(region="all"))
    r_xy = np.linalg.norm((vol.points() - vol.center)[:, :2], axis=1)
    assert ev.tre_mean == pytest.approx(np.mean(2 * r_xy * math.sin(math.radians(1.0))))
    assert ev.d_rotation == pytest.approx(2.0) and ev.errors["angle_z"] == pytest.approx(2.0)


def test_grid_prominence_and_the_overlap_bound():
    thetas = np.zeros((6, 3))
    grid = GridSearch(thetas, np.array([1.0, 2.0, 3.0, 4.0, 10.0, 50.0]), np.array([1.0, 1, 1, 1, 1, 0.1]), 1.0, 5,
                      0.25)
    assert grid.prominence(10.0) == pytest.approx(7.0)  # median 3, median absolute deviation 1
    assert grid.values[-1] == -math.inf and grid.values_at(0.05)[-1] == 50.0
    flat = GridSearch(thetas[:3], np.ones(3), np.ones(3), 1.0, 3, 0.25)
    assert flat.prominence(2.0) == math.inf and flat.prominence(math.nan) == -math.inf


def test_sample_mask_in_3d_grows_the_cube_by_the_margin_in_voxels():
    data = np.zeros((20, 20, 20))
    data[5:15, 5:15, 5:15] = 1.0
    vol = Image(data, (2.0, 2.0, 2.0))
    params = for_dimension(RegisterParams(sampling={"margin": 4.0}), 3)
    assert int(sample_mask(vol, params).sum()) == 14 ** 3
    assert sample_mask(vol, for_dimension(RegisterParams(sampling={"region": "all"}), 3)) is None


@pytest.mark.parametrize("d", [2, 3])
def test_smoothed_is_a_gaussian_of_sigma_over_each_axis_spacing(d):
    data = np.random.default_rng(d).random((8,) * d)
    spacing = (1.0, 2.0, 4.0)[:d]
    out = Image(data, spacing).smoothed(2.0).data
    np.testing.assert_array_equal(out, gaussian_blur(data, [2.0 / s for s in spacing][::-1]))


def test_border_counts_every_face():
    assert int(border((4, 5)).sum()) == 4 * 5 - 2 * 3
    assert int(border((4, 5, 6)).sum()) == 4 * 5 * 6 - 2 * 3 * 4


@pytest.mark.parametrize("d", [2, 3])
def test_object_mask_fills_a_ring_or_a_shell(d):
    grids = np.meshgrid(*[np.arange(40.0) - 19.5] * d, indexing="ij")
    r = np.sqrt(sum(g ** 2 for g in grids))
    ring = ((r > 6) & (r < 14)).astype(float)
    np.testing.assert_array_equal(object_mask(Image(ring)), r < 14)


def test_euler_angles_at_gimbal_lock_rebuild_the_matrix():
    for ax in (math.pi / 2, -math.pi / 2):
        R = euler_matrix((ax, 0.3, -0.7))
        np.testing.assert_allclose(euler_matrix(euler_angles(R)), R, atol=1e-12)


def test_describe_writes_the_parameters():
    assert describe(RigidTransform.euler2d(13.1, 15.9, 10.0, (0.0, 0.0))) == "(angle +10.0 deg, t = 13.1, 15.9)"
    t3 = RigidTransform((math.radians(1.0), 0.0, math.radians(-2.5), 1.0, 2.0, 3.0), (0.0, 0.0, 0.0))
    assert describe(t3) == "(angles +1.0 +0.0 -2.5 deg, t = 1.0, 2.0, 3.0)"


@pytest.mark.parametrize("d", [2, 3])
def test_search_score_is_jt_of_the_joint_histogram_counted_by_hand(d):
    """At the native spacing and a whole-pixel shift, the coarse search's score is JT (order 2) of the joint histogram
    of the overlapping pixels' bins (fixed pixel p against moving pixel p + shift), and its overlap the fraction of
    fixed pixels whose partner exists."""
    from topomatch.stages.registration.divergence import jensen_tsallis_histogram
    from topomatch.stages.registration.histogram import Binning
    from topomatch.stages.registration.search import SEARCH_BINS, SearchImages

    shape = (14, 15, 9)[:d]
    rng = np.random.default_rng(d)
    fixed, moving = Image(rng.random(shape)), Image(rng.random(shape) ** 2)
    images = SearchImages(fixed, moving, center=fixed.center, min_overlap=0.0, spacing=1.0)
    theta = np.r_[np.zeros(3 * d - 3 - d), [2.0, -1.0, 1.0][:d]]  # x +2, y -1 (, z +1)
    values, inside = images.scores_and_overlaps(theta, np.zeros((1, d), dtype=np.intp))
    fb, mb = Binning.of(fixed.data, SEARCH_BINS), Binning.of(moving.data, SEARCH_BINS)
    shift = [int(v) for v in theta[-d:][::-1]]  # array order: (z,) y, x
    f_cut = tuple(slice(max(0, -s), n - max(0, s)) for s, n in zip(shift, shape))
    m_cut = tuple(slice(max(0, s), n - max(0, -s)) for s, n in zip(shift, shape))
    h = np.zeros((fb.bins, mb.bins))
    np.add.at(h, (fb.index(fixed.data[f_cut]).ravel(), mb.index(moving.data[m_cut]).ravel()), 1.0)
    assert inside[0] == pytest.approx(h.sum() / fixed.data.size)
    assert values[0] == pytest.approx(jensen_tsallis_histogram(h, 2.0), rel=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_make_case_moves_the_source_by_its_truth(d):
    """On a linear ramp (which N-linear interpolation reproduces exactly) without noise or crop, the case's moving
    image mapped back by the case's truth is the source, away from the border; the truth is the first draw of
    ``default_rng([seed, index])``."""
    from topomatch.stages.registration.interpolation import resample
    from topomatch.stages.registration.misalign import make_case, random_transform

    shape = (24, 26, 28)[:d]
    grids = np.meshgrid(*[np.arange(n, dtype=float) for n in shape], indexing="ij")
    source = Image(5.0 + sum((k + 2.0) * g for k, g in enumerate(grids)), (1.0, 1.5, 2.0)[:d])
    case = make_case(source, 3, seed=7, multimodal=False, crop=False, max_angle=8.0, max_translation=2.0, noise=0.0)
    expected = random_transform(np.random.default_rng([7, 3]), source.center, max_angle=8.0, max_translation=2.0)
    assert case.truth == expected
    back = resample(case.moving, case.truth, source)
    core = tuple(slice(n // 2 - 4, n // 2 + 4) for n in shape)
    np.testing.assert_allclose(back[core], source.data[core], atol=1e-9)
    np.testing.assert_array_equal(case.fixed.data, source.data)


@pytest.mark.parametrize("d", [2, 3])
def test_histogram_positions_are_the_moving_indices_of_the_mapped_samples(d):
    """Without jitter, sample p's moving index is ``moving.continuous_index(T(p))`` (ITK order); ``shuffled`` keeps
    both marginals and the sample count."""
    from topomatch.stages.registration.histogram import Binning, JointHistogram

    rng = np.random.default_rng(d)
    shape = (9, 10, 11)[:d]
    fixed = Image(rng.random(shape), (1.0, 1.5, 2.0)[:d], (3.0, -2.0, 1.0)[:d])
    direction = np.linalg.qr(rng.normal(size=(d, d)))[0]
    moving = Image(rng.random((8, 12, 7)[:d]), (2.0, 1.0, 1.5)[:d], (-1.0, 4.0, 2.0)[:d], direction)
    jh = JointHistogram(fixed, moving, Binning.of(fixed.data, 8), Binning.of(moving.data, 8), center=fixed.center,
                        mode="linear")
    t = RigidTransform(tuple(rng.normal(scale=0.2, size=3 * d - 3 - d)) + tuple(rng.normal(size=d)), fixed.center)
    np.testing.assert_allclose(jh.positions(np.asarray(t.parameters)), moving.continuous_index(t.apply(fixed.points())).T,
                               atol=1e-9)
    h, n = jh(np.zeros(3 * d - 3))
    hs, ns = jh.shuffled(5)(np.zeros(3 * d - 3))
    assert ns == n
    np.testing.assert_allclose(hs.sum(axis=0), h.sum(axis=0), atol=1e-9)  # moving marginal: the same samples
    np.testing.assert_allclose(hs.sum(axis=1), h.sum(axis=1), atol=1e-9)  # fixed marginal: permuted, same counts


def test_objective_in_3d_undefined_below_its_overlap_and_weighted_by_it():
    """A volume against itself shifted by a third of its i extent: 2/3 of the samples inside; the measure times the
    overlap to ``overlap_power``; -inf once ``min_overlap`` exceeds it (``on`` keeps the settings, or changes it)."""
    from topomatch.stages.registration.histogram import Binning, JointHistogram
    from topomatch.stages.registration.objective import Objective

    vol = Image(np.random.default_rng(0).random((6, 7, 9)), (1.0, 1.0, 2.0))
    b = Binning.of(vol.data, 8)
    jh = JointHistogram(vol, vol, b, b, center=vol.center, mode="linear")
    theta = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 0.0])  # 3 of the 9 columns (i: 1 mm each) leave the grid
    plain = Objective(jh, "jt", min_overlap=0.5)
    weighted = Objective(jh, "jt", min_overlap=0.5, overlap_power=1.0)
    assert plain.overlap(theta) == pytest.approx(6 / 9)
    assert weighted(theta) == pytest.approx(plain(theta) * 6 / 9)
    assert plain.on(jh, min_overlap=0.7)(theta) == -math.inf and plain.on(jh)(theta) == plain(theta)


def test_misalign_pair_moves_the_moving_image_by_its_transform():
    from topomatch.stages.registration.misalign import MisalignParams, misalign_pair

    rng = np.random.default_rng(3)
    fixed, moving = Image(rng.random((20, 22))), Image(rng.random((20, 22)))
    params = MisalignParams(theta=[7.0, 2.0, -3.0], order=1)
    out = misalign_pair(fixed, moving, {"angle": 0.0, "tx": 0.0, "ty": 0.0}, params=params)
    truth = RigidTransform.from_degrees([7.0, 2.0, -3.0], fixed.center)
    np.testing.assert_array_equal(out.moving.data, moved(moving, truth, order=1).data)
    assert out.truth == pytest.approx({"angle": 7.0, "tx": 2.0, "ty": -3.0})


def test_accuracy_rows_count_by_hand():
    from types import SimpleNamespace

    from topomatch.stages.registration.reports import accuracy_rows

    evs = [SimpleNamespace(method="m", tre_mean=t, seconds=s, flagged=f)
           for t, s, f in ((0.5, 1.0, False), (2.0, 2.0, False), (0.8, 4.0, True))]
    (row,) = [r for r in accuracy_rows([("g", e) for e in evs], 1.0) if r["pairs"] == "all"]
    assert row["success_rate"] == pytest.approx(2 / 3) and row["median_tre"] == 0.8 and row["max_tre"] == 2.0
    assert (row["failed_unflagged"], row["ok_but_flagged"], row["failed_and_flagged"], row["flagged"]) == (1, 1, 0, 1)
    assert row["median_seconds"] == 2.0 and row["mean_seconds"] == pytest.approx(7 / 3)


def test_accuracy_summary_counts_a_repeat_once_and_two_contrasts_of_one_input_twice():
    """Two contrasts of one input (a sweep over ``misalign.contrast``: the same truth, other estimates) are two cases;
    one registration reached again at another sweep point of a later stage (the same estimate) is one."""
    from types import SimpleNamespace

    from topomatch.stages.registration.evaluate import EvaluateResult
    from topomatch.stages.registration.reports import AccuracyParams, accuracy_summary_report

    def item(error: float):
        ev = EvaluateResult(method="m", errors={"angle": error, "tx": 0.0, "ty": 0.0}, d_rotation=abs(error),
                            d_translation=0.0, tre_mean=abs(error), tre_max=abs(error), success=True, flagged=False,
                            seconds=1.0, truth={"angle": 5.0, "tx": 1.0, "ty": 2.0})
        return SimpleNamespace(input_label="{bundled}/a.png", input_path="a.png", results={"evaluate": ev})

    out = accuracy_summary_report(None, [item(0.1), item(0.3), item(0.1)], AccuracyParams())
    (row,) = [r for r in out.tables["accuracy"] if r["pairs"] == "all"]
    assert row["cases"] == 2 and row["median_tre"] == pytest.approx(0.2)


@pytest.mark.parametrize("d", [2, 3])
def test_before_after_resamples_by_the_identity_then_the_transform(d):
    from topomatch.stages.registration.reports import before_after

    b = np.random.default_rng(d).random((5, 6, 7)[:d])
    image = Image(b)
    shift = RigidTransform((0.0,) * (3 * d - 3 - d) + (1.0,) + (0.0,) * (d - 1), tuple(image.center))  # x + 1
    before, after = before_after(image, image, shift)
    np.testing.assert_allclose(before, b, atol=1e-12)
    np.testing.assert_allclose(after[..., :-1], b[..., 1:], atol=1e-12)  # moving(p + 1 along x)
    assert np.all(after[..., -1] == b.min())
