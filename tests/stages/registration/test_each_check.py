"""Each test of the self-check on its own, with an answer known in advance.

``register`` asks every test at its own result; here each ``check_*`` function is asked at transforms chosen by
hand, on a run (``_Run``: the pyramid, bounds and samples ``register`` would build) of a pair whose truth is known:
the PD slice moved by a known rigid transform, a disc (rotationally symmetric: its rotation is undetermined; its
overlap with a shifted copy is the lens area), pure noise (chance), a pair whose truth overlaps less than
``min_overlap``. Both ways: the test fires where it must and stays quiet at the truth.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from topomatch.stages.registration import register as reg
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.misalign import moved
from topomatch.stages.registration.params import RegisterParams, for_dimension
from topomatch.stages.registration.structure import object_mask
from topomatch.stages.registration.transform import RigidTransform, euler_matrix

TRUTH = np.array([math.radians(8.0), 6.0, -4.0])  # (angle in radians, tx, ty): the run's parameters


def make_run(fixed: Image, moving: Image, **check) -> reg._Run:
    """The run ``register`` builds for this pair with the defaults (``check`` fields overridden), ready for checks."""
    params = for_dimension(RegisterParams(check=check), fixed.dim)
    run = reg._Run(fixed, moving, params, reg.sample_mask(fixed, params), None)
    run.measures, run.better = {}, None
    return run


def ask(check, run: reg._Run, theta, stop: str = "") -> list[str]:
    """The names of the flags ``check`` raises at ``theta`` (its finest-level value computed as register does)."""
    theta = np.asarray(theta, dtype=np.float64)
    return [f.check for f in check(run, theta, run.levels[-1].objective(theta), stop)]


def disc_image(radius: float = 30.0, n: int = 128, spacing: float = 1.0, centre=None, seed: int = 0) -> Image:
    """A disc of 100 on 0 with noise of deviation 2 (n x n pixels), centred on the grid unless ``centre``."""
    yy, xx = np.mgrid[0:n, 0:n].astype(float)
    cy, cx = ((n - 1) / 2,) * 2 if centre is None else centre
    data = np.where(np.hypot(xx - cx, yy - cy) < radius, 100.0, 0.0)
    return Image(data + np.random.default_rng(seed).normal(0, 2.0, (n, n)), spacing=(spacing, spacing), name="disc")


def lens_fraction(d: float, radius: float) -> float:
    """Area shared by two discs of ``radius`` whose centres are ``d`` apart, over a disc's area."""
    return (2 * radius ** 2 * math.acos(d / (2 * radius)) - 0.5 * d * math.sqrt(4 * radius ** 2 - d ** 2)) \
        / (math.pi * radius ** 2)


@pytest.fixture(scope="module")
def pd_run(pd_slice):
    return make_run(pd_slice, moved(pd_slice, RigidTransform(tuple(TRUTH), tuple(pd_slice.center))))


def test_start_flags_a_stop_before_any_step_or_a_start_without_overlap(pd_run):
    assert ask(reg.check_start, pd_run, TRUTH, "invalid_start") == ["start"]
    assert ask(reg.check_start, pd_run, TRUTH, "flat_objective") == ["start"]
    assert ask(reg.check_start, pd_run, TRUTH, "max_iterations") == []
    start = pd_run.start
    try:
        pd_run.start = np.r_[0.0, 1000.0, 0.0]  # the moving image 1000 px away: nothing overlaps
        flags = reg.check_start(pd_run, TRUTH, 0.4, "max_iterations")
        assert [f.check for f in flags] == ["start"] and "no overlap" in flags[0].message
        assert "only 0.0% of the fixed samples" in flags[0].message
    finally:
        pd_run.start = start


def test_overlap_flags_an_undefined_measure_only(pd_run):
    far = np.r_[0.0, 1000.0, 0.0]
    assert not math.isfinite(pd_run.levels[-1].objective(far))
    assert ask(reg.check_overlap, pd_run, far) == ["overlap"]
    assert ask(reg.check_overlap, pd_run, TRUTH) == []


def test_bounds_flag_exactly_the_parameters_within_one_unit_of_a_bound(pd_run):
    """One unit is a pixel for a translation and a pixel's arc at the RMS radius for the angle (``run.scales``)."""
    unit = pd_run.scales
    inside = 0.5 * (pd_run.lower + pd_run.upper)
    assert ask(reg.check_bounds, pd_run, inside) == []
    for i, name in enumerate(("angle", "tx", "ty")):
        near, clear = inside.copy(), inside.copy()
        near[i], clear[i] = pd_run.lower[i] + 0.99 * unit[i], pd_run.lower[i] + 1.01 * unit[i]
        flags = reg.check_bounds(pd_run, near, 0.4, "")
        assert [f.check for f in flags] == ["bounds"] and f"bound of {name} (" in flags[0].message
        assert ask(reg.check_bounds, pd_run, clear) == []
    flags = reg.check_bounds(pd_run, pd_run.upper, 0.4, "")
    assert "bound of angle, tx, ty (" in flags[0].message


def test_chance_is_the_measure_over_its_shuffled_pairing(pd_run, pd_slice):
    """At the truth the measure is hundreds of times its chance level; against noise (independent of the fixed image)
    it is its own chance level: the ratio is 1 up to sampling, below the 3D default's 3, which flags it."""
    fine = pd_run.levels[-1].objective
    pd_run.measures = {}
    assert ask(reg.check_chance, pd_run, TRUTH) == []
    chance = fine.on(fine.histogram.shuffled(pd_run.params.seed))(TRUTH)
    assert pd_run.measures["chance"] == pytest.approx(fine(TRUTH) / chance, rel=1e-12) and chance > 0
    assert pd_run.measures["chance"] > 100
    noise = pd_slice.with_data(np.random.default_rng(5).normal(100.0, 30.0, pd_slice.shape), name="noise")
    run = make_run(pd_slice, noise, chance=3.0)
    assert ask(reg.check_chance, run, TRUTH) == ["chance"]
    assert 0.5 < run.measures["chance"] < 2.0


def test_gain_flags_no_climb_an_ascent_one_unit_away_and_a_zero_measure(pd_run):
    fine = pd_run.levels[-1].objective
    pd_run.measures = {}
    assert ask(reg.check_gain, pd_run, TRUTH) == [] and pd_run.measures["ascent"] < 0  # an optimum: every step falls
    off = TRUTH + np.r_[0.0, 3.0, 0.0]  # 3 px along tx from the truth: one pixel back climbs
    pd_run.measures = {}
    assert ask(reg.check_gain, pd_run, off) == ["gain"]
    by_hand = max((fine(off + s * u) - fine(off)) / fine(off) for u in np.diag(pd_run.scales) for s in (-1, 1))
    assert pd_run.measures["ascent"] == pytest.approx(by_hand, rel=1e-12) and by_hand > pd_run.params.check.margin
    start = pd_run.start
    try:  # started at the truth, ended 5 px away and lower: moved without climbing
        pd_run.start = TRUTH.copy()
        flags = reg.check_gain(pd_run, TRUTH + np.r_[0.0, 5.0, 0.0], fine(TRUTH + np.r_[0.0, 5.0, 0.0]), "")
        assert [f.check for f in flags] == ["gain"] and "no better than at the start" in flags[0].message
    finally:
        pd_run.start = start
    flags = reg.check_gain(pd_run, pd_run.start, 0.0, "")
    assert [f.check for f in flags] == ["gain"] and "is 0 at the result" in flags[0].message


def test_consistency_is_the_coarser_levels_drop_at_the_result(pd_run):
    """With every level ending at the truth and the result 4 px away, the measure is each coarser level's relative
    drop from its end to the result, computed here by hand; a result at the coarse ends is not judged."""
    pd_run.ends = [TRUTH.copy() for _ in pd_run.levels]
    try:
        result = TRUTH + np.r_[0.0, 4.0, 0.0]
        drops = [1.0 - lv.objective(result) / lv.objective(TRUTH) for lv in pd_run.levels[:-1]]
        pd_run.measures = {}
        flagged = ask(reg.check_consistency, pd_run, result)
        first_over = next((d for d in drops if d > pd_run.params.check.consistency), None)
        assert first_over is not None and flagged == ["consistency"]
        assert pd_run.measures["consistency"] == pytest.approx(max(drops[: drops.index(first_over) + 1]), rel=1e-12)
        pd_run.measures = {}
        assert ask(reg.check_consistency, pd_run, TRUTH) == [] and "consistency" not in pd_run.measures
    finally:
        pd_run.ends = []


def test_stability_measures_the_rerun_on_another_sample(pd_slice):
    moving = moved(pd_slice, RigidTransform(tuple(TRUTH), tuple(pd_slice.center)))
    run = make_run(pd_slice, moving, stability=0.5)
    assert ask(reg.check_stability, run, TRUTH) == [] and 0 <= run.measures["stability"] < 0.5
    strict = make_run(pd_slice, moving, stability=1e-9)  # no second sample ends at exactly the same point
    assert ask(reg.check_stability, strict, TRUTH) == ["stability"] and strict.measures["stability"] > 0
    assert ask(reg.check_stability, make_run(pd_slice, moving), TRUTH) == []  # 2D default: 0, not asked


def test_agreement_flags_a_result_mutual_information_climbs_away_from(pd_run):
    pd_run.measures = {}
    assert ask(reg.check_agreement, pd_run, TRUTH) == [] and pd_run.measures["agreement"] < 0.5
    off = TRUTH + np.r_[0.0, 3.0, 0.0]
    pd_run.measures = {}
    assert ask(reg.check_agreement, pd_run, off) == ["agreement"]
    assert 1.0 < pd_run.measures["agreement"] <= 3.5  # MI climbs back toward the truth, 3 px away


def test_overlap_bound_flags_a_result_whose_measure_rises_past_the_accepted_overlap(pd_slice, pd_run):
    """The truth overlaps 21 % (below min_overlap 25 %): at a transform between it and the start that overlaps
    27-30 %, the measure with half the overlap accepted climbs toward it, below 25 % overlap."""
    truth = np.array([math.radians(-40.0), 84.0, -112.0])
    run = make_run(pd_slice, moved(pd_slice, RigidTransform(tuple(truth), tuple(pd_slice.center))))
    coarse = run.levels[0].objective
    assert coarse.overlap(truth) < run.params.metric.min_overlap
    near = next(t for t in (truth + s * (run.start - truth) for s in np.linspace(0, 1, 101))
                if coarse.overlap(t) >= 0.27)
    assert coarse.overlap(near) <= 0.30
    flags = reg.check_overlap_bound(run, near, run.levels[-1].objective(near), "")
    assert [f.check for f in flags] == ["overlap_bound"]
    assert ask(reg.check_overlap_bound, pd_run, TRUTH) == []


@pytest.mark.parametrize("d", [0.0, 10.0, 20.0, 40.0])
def test_content_is_the_lens_of_two_shifted_discs(d):
    """A disc against itself shifted by d: the fixed content landing on the moving content is the lens area over
    the disc's area (to the search copy's pixels); below ``min_content`` (20 %) it flags."""
    disc = disc_image()
    run = make_run(disc, disc)
    flagged = ask(reg.check_content, run, np.r_[0.0, d, 0.0])
    assert run.measures["content"] == pytest.approx(lens_fraction(d, 30.0), abs=0.01)
    assert flagged == ([] if lens_fraction(d, 30.0) >= 0.2 else ["content"])
    assert ask(reg.check_content, run, np.r_[0.0, 45.0, 0.0]) == ["content"]  # lens 12 %


@pytest.mark.parametrize("d", [0.0, 20.0, 45.0])
def test_content_of_an_outline_drawing_is_its_inside(d):
    """A disc against its outline drawn 2 pixels wide (a bright ring on black, as an outline image is; thirty-third
    round): the ring's inside is content, so the measure is the lens of the two discs as above (before the round only
    the ring counted and the aligned pair scored 0.1, flagged)."""
    disc = disc_image()
    yy, xx = np.mgrid[0:128, 0:128].astype(float)
    r = np.hypot(xx - 63.5, yy - 63.5)
    ring = disc.with_data(np.where((r < 30.0) & (r >= 28.0), 100.0, 0.0) + np.random.default_rng(1).normal(0, 2.0, r.shape))
    run = make_run(disc, ring)
    flagged = ask(reg.check_content, run, np.r_[0.0, d, 0.0])
    assert run.measures["content"] == pytest.approx(lens_fraction(d, 30.0), abs=0.05)
    assert flagged == ([] if lens_fraction(d, 30.0) >= 0.2 else ["content"])


def label_pair(image: Image) -> tuple[Image, Image]:
    """(a three-class label map of ``image``'s object, 0 outside; ``image`` moved by TRUTH)."""
    obj = object_mask(image)
    q = np.quantile(image.data[obj], [1 / 3, 2 / 3])
    labels = image.with_data(np.where(obj, 1.0 + (image.data > q[0]) + (image.data > q[1]), 0.0))
    return labels, moved(image, RigidTransform(tuple(TRUTH), tuple(image.center)))


def test_label_registers_a_label_maps_object_and_flags_a_result_away_from_it(pd_slice):
    """A three-class label map of the PD slice (fixed) against the slice moved by TRUTH: the label test registers the
    map's object against the slice (an outline-only pair, right to a third of a pixel here) and measures how far the
    result lies from that answer, so a result 8 px or 10 degrees off measures that distance (an angle: its arc at the
    RMS radius) and flags; at the truth it passes. Off at 0, and never asked of an image that is not a label map. The
    test only flags: the registration's own answer is the same with it off."""
    labels, image = label_pair(pd_slice)
    run = make_run(labels, image)
    for off, flagged in ((np.zeros(3), []), (np.r_[0.0, 8.0, 0.0], ["label"]), (np.r_[math.radians(10), 0, 0], ["label"])):
        run.measures = {}
        assert ask(reg.check_label, run, TRUTH + off) == flagged
        assert run.measures["label"] == pytest.approx(run.distance(TRUTH + off, TRUTH), abs=0.35)
    run.measures = {}
    theta = TRUTH + np.r_[0.0, 8.0, 0.0]
    [flag] = reg.check_label(run, theta, run.levels[-1].objective(theta), "")
    assert "the fixed image reads as a label map" in flag.message and "registers at (angle +" in flag.message
    for other in (make_run(labels, image, label=0.0), make_run(pd_slice, image)):
        other.measures = {}
        assert ask(reg.check_label, other, TRUTH + np.r_[0.0, 8.0, 0.0]) == [] and other.measures == {}
    on, off = reg.register(labels, image), reg.register(labels, image, {"check": {"label": 0.0}})
    assert on.transform.parameters == off.transform.parameters and "label" in on.measures


def test_label_trusts_an_answer_that_passes_reads_three_values_and_takes_the_pixels_above_the_minimum(pd_slice,
                                                                                                       monkeypatch):
    """The label test flags only when its object's answer passes that registration's own self-check (a flagged answer
    is measured, not trusted); it is not asked of an outline-only pair; a two-valued image (a thresholded one) is no
    label map; and the object is the pixels above the map's minimum, whatever that minimum is (the map + 10 gives
    the same answer)."""
    labels, image = label_pair(pd_slice)
    off = TRUTH + np.r_[0.0, 8.0, 0.0]
    real = reg.register
    monkeypatch.setattr(reg, "register", lambda *a, **k: dataclasses.replace(real(*a, **k), flags=(reg.Flag("x", "x"),)))
    run = make_run(labels, image)
    run.measures = {}
    assert ask(reg.check_label, run, off) == [] and run.measures["label"] == pytest.approx(8.0, abs=0.35)
    monkeypatch.undo()
    run.measures, run.outline_only = {}, True
    assert ask(reg.check_label, run, off) == [] and "label" not in run.measures
    binary = make_run(labels.with_data((labels.data >= 2).astype(np.float64)), image)
    binary.measures, binary.outline_only = {}, False
    assert ask(reg.check_label, binary, off) == [] and "label" not in binary.measures
    shifted = make_run(labels.with_data(labels.data + 10.0), image)
    shifted.measures = {}
    assert ask(reg.check_label, shifted, off) == ["label"]
    assert shifted.measures["label"] == pytest.approx(8.0, abs=0.35)


def test_flatness_finds_the_rotation_a_disc_leaves_undetermined(pd_run):
    """A disc centred on the grid looks the same at every angle about its centre: the measure does not fall along
    the rotation (ratio 0), and the flag names that direction: all angle, no translation. (Each image has noise of
    its own: the same noise in both would pin every parameter, the rotation too, at the identity.)"""
    run = make_run(disc_image(seed=0), disc_image(seed=1))
    flags = reg.check_flatness(run, np.zeros(3), run.levels[-1].objective(np.zeros(3)), "")
    assert [f.check for f in flags] == ["flatness"] and run.measures["flatness"] < 0.01
    assert "+0.00 tx, +0.00 ty" in flags[0].message
    pd_run.measures = {}
    assert ask(reg.check_flatness, pd_run, TRUTH) == [] and pd_run.measures["flatness"] > 0.3


def test_outline_flags_outlines_apart_a_coarse_optimum_left_and_an_object_cut_by_the_border():
    """A disc mask against itself (an outline-only pair), on 2 mm pixels: shifted by d up to the band (4 px) the
    outlines lie 2 (pi R^2 - lens) / (2 pi R) apart (the area between them over the outline's length, to 6 % for
    the pixel outline's length), and pass; shifted 12 px (24 mm) the gap, saturated by the band, still exceeds
    ``outline_gap`` (6 mm) and flags."""
    disc = disc_image(spacing=2.0)
    run = make_run(disc, disc)
    assert run.outline_only
    r = 60.0  # mm
    for px in (0.0, 1.0, 2.0, 3.0):
        assert ask(reg.check_outline, run, np.r_[0.0, 2.0 * px, 0.0]) == []
        assert run.measures["outline_gap"] == pytest.approx(r * (1 - lens_fraction(2.0 * px, r)), rel=0.06, abs=0.05)
        assert run.measures["outline_view"] == 1.0  # the disc is clear of the border and seen whole
    assert ask(reg.check_outline, run, np.r_[0.0, 24.0, 0.0]) == ["outline"]
    assert run.measures["outline_gap"] > run.params.check.outline_gap
    # every level ended at the truth and the result is 1 px (2 mm) off, the outlines 1.2 mm apart: the coarser
    # levels' measures fall there on their own samples and on 8 others (twenty-ninth round), and the drop flags
    run.ends = [np.zeros(3)] * len(run.levels)
    shifted = np.r_[0.0, 2.0, 0.0]
    run.measures = {"consistency": max(d for _, d in run.drops(shifted))}
    assert run.measures["consistency"] > run.params.check.outline_drop
    assert ask(reg.check_outline, run, shifted) == ["outline"]
    assert run.measures["outline_drop"] > 0
    # a drop of the run's own samples that the levels' other samples do not show (here: none, every level ended at
    # the result) does not flag
    run.ends, run.measures = [shifted] * len(run.levels), {"consistency": 2 * run.params.check.outline_drop}
    assert ask(reg.check_outline, run, shifted) == [] and run.measures["outline_drop"] == 0.0
    corner = disc_image(radius=60.0, centre=(0.0, 0.0))  # a quarter disc: its arc's pixel faces number 60 + 60,
    run = make_run(corner, corner)                        # as do its faces on the border: half is outline
    assert ask(reg.check_outline, run, np.zeros(3)) == [] and run.measures["outline_view"] == pytest.approx(0.5)
    rows = np.mgrid[0:128, 0:128][0]  # the top 40 rows: outline 128 faces, border 128 + 2 x 40
    band = Image(100.0 * (rows < 40) + np.random.default_rng(0).normal(0, 2.0, rows.shape))
    run = make_run(band, band)
    assert ask(reg.check_outline, run, np.zeros(3)) == ["outline"]
    assert run.measures["outline_view"] == pytest.approx(128 / (256 + 80))
    assert 128 / (256 + 80) < run.params.check.min_outline_view
    # the top 10 rows: 128 / (256 + 20) = 0.46 of the boundary is outline, under half: refused in 2D since the
    # forty-second round (0.5), passed at 3D's limit (0.45) asked for here
    band = Image(100.0 * (rows < 10) + np.random.default_rng(0).normal(0, 2.0, rows.shape))
    for limit, flags in ((None, ["outline"]), (0.45, [])):
        run = make_run(band, band) if limit is None else make_run(band, band, min_outline_view=limit)
        assert ask(reg.check_outline, run, np.zeros(3)) == flags
        assert run.measures["outline_view"] == pytest.approx(128 / (256 + 20))
    assert for_dimension(RegisterParams(), 3).check.min_outline_view == 0.45
    # rows 20-109, cut by the left and right borders: 256 / (256 + 180) = 0.59 of the boundary is outline, above the
    # 2D limit but under 1.2 times it, so a flat measure one unit from the result refuses it (forty-third round)
    band = Image(100.0 * ((rows >= 20) & (rows < 110)) + np.random.default_rng(0).normal(0, 2.0, rows.shape))
    for ascent, limit, flags in ((-0.01, None, ["outline"]), (-0.05, None, []), (-0.01, 0.0, [])):
        run = make_run(band, band) if limit is None else make_run(band, band, outline_flat=limit)
        run.measures = {"ascent": ascent}
        assert ask(reg.check_outline, run, np.zeros(3)) == flags
        assert run.measures["outline_view"] == pytest.approx(256 / (256 + 180))


def test_prominence_separates_the_truth_from_a_typical_transform(pd_run):
    pd_run.measures = {}
    assert ask(reg.check_prominence, pd_run, TRUTH) == [] and pd_run.measures["prominence"] > 20
    far = TRUTH + np.r_[math.radians(150.0), 20.0, 10.0]
    pd_run.measures = {}
    assert ask(reg.check_prominence, pd_run, far) == ["prominence"]
    assert pd_run.measures["prominence"] < pd_run.params.check.min_prominence


def test_prominence_says_so_when_no_search_transform_overlaps_enough(pd_slice):
    """A moving image a quarter of the fixed grid, with a 90 % overlap bound: no transform of the coarse search keeps
    90 % of the fixed samples inside it, the prominence is -inf and the flag says why instead of printing -inf."""
    h, w = pd_slice.shape
    moving = Image(pd_slice.data[h // 4: 3 * h // 4, w // 4: 3 * w // 4], origin=(w // 4, h // 4))
    params = for_dimension(RegisterParams(metric={"min_overlap": 0.9}), 2)
    run = reg._Run(pd_slice, moving, params, reg.sample_mask(pd_slice, params), None)
    run.measures, run.better = {}, None
    flags = reg.check_prominence(run, np.zeros(3), 0.0, "")
    assert [f.check for f in flags] == ["prominence"] and run.measures["prominence"] == -math.inf
    assert "no transform of a coarse search overlaps enough" in flags[0].message and "-inf" not in flags[0].message


def test_capture_finds_the_truth_from_a_wrong_basin_and_offers_it(pd_run):
    """At a transform 150 deg and 22 px from the truth, a better basin is found and, run through the schedule, ends
    at the truth (``run.better``, which ``register`` adopts with ``check.retry``); at the truth nothing is better."""
    far = TRUTH + np.r_[math.radians(150.0), 20.0, 10.0]
    assert ask(reg.check_capture, pd_run, far) == ["capture"]
    assert pd_run.better is not None and pd_run.distance(pd_run.better[0], TRUTH) < 0.5
    pd_run.better = None
    assert ask(reg.check_capture, pd_run, TRUTH) == [] and pd_run.better is None


def test_capture_keeps_a_probe_whose_first_level_refine_ends_lower(pd_run, monkeypatch):
    """A probe at the truth scores above a wrong result at the first level, and its refine climbs away from it, down
    into the result's basin (a first level whose steps overshoot a narrow peak: a pair of label maps, thirty-eighth
    round): the probe is kept, so the better basin is still found and, run through the schedule, ends at the truth."""
    far = TRUTH + np.r_[math.radians(150.0), 20.0, 10.0]
    first = pd_run.levels[0].objective
    assert first(TRUTH) > first(far)
    monkeypatch.setattr(pd_run, "candidates", lambda theta, n=None: [TRUTH.copy()])
    monkeypatch.setattr(pd_run, "refine", lambda start, objective=None: (far.copy(), first(far)))
    assert ask(reg.check_capture, pd_run, far) == ["capture"]
    assert pd_run.better is not None and pd_run.distance(pd_run.better[0], TRUTH) < 0.5
    pd_run.better = None


# --------------------------------------------------------------------------- the same tests in 3D

TRUTH3 = np.array([0.10, -0.05, 0.08, 4.0, -3.0, 2.0])  # (three angles in radians, tx, ty, tz)


def test_mirror_flags_a_moving_image_flipped_front_to_back_and_not_the_unflipped_one(pd_slice, pd_run):
    """A flip no rigid transform undoes (44th round; a hostile user's mirrored sagittal slice passed): the moved PD
    slice mirrored along its rows (front to back: the brain is not symmetric that way) is registered to some pose, and
    the mirrored pair (the unflipped image) refined from its best coarse transforms beats that pose by far; the
    unflipped pair at its truth is quiet, its mirror (left-right: nearly the same brain) scoring below it."""
    assert ask(reg.check_mirror, pd_run, TRUTH) == [] and 0.5 < pd_run.measures["mirror"] < 1.0
    moving = moved(pd_slice, RigidTransform(tuple(TRUTH), tuple(pd_slice.center)))
    result = reg.register(pd_slice, moving.with_data(moving.data[::-1].copy()))
    assert "mirror" in [f.check for f in result.flags] and result.measures["mirror"] > 1.5
    off = make_run(pd_slice, moving, mirror=0.0)
    assert ask(reg.check_mirror, off, TRUTH) == [] and "mirror" not in off.measures


def ball_image(radius: float = 14.0, n: int = 48, seed: int = 0) -> Image:
    """A ball of 100 on 0 with noise of deviation 2 (n^3 voxels of 1 mm), centred on the grid."""
    zz, yy, xx = np.mgrid[0:n, 0:n, 0:n].astype(float) - (n - 1) / 2
    data = np.where(np.sqrt(xx ** 2 + yy ** 2 + zz ** 2) < radius, 100.0, 0.0)
    return Image(data + np.random.default_rng(seed).normal(0, 2.0, data.shape), name="ball")


@pytest.fixture(scope="module")
def t1_run():
    from tests_paths import ITK_DIR
    from topomatch.stages.registration.io import read_image

    t1 = read_image(ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz").shrink((2, 2, 1))
    return make_run(t1, moved(t1, RigidTransform(tuple(TRUTH3), tuple(t1.center))))


def test_3d_bounds_flag_exactly_the_parameters_within_one_unit_of_a_bound(t1_run):
    unit, inside = t1_run.scales, 0.5 * (t1_run.lower + t1_run.upper)
    assert ask(reg.check_bounds, t1_run, inside) == []
    for i, name in enumerate(("angle_x", "angle_y", "angle_z", "tx", "ty", "tz")):
        near, clear = inside.copy(), inside.copy()
        near[i], clear[i] = t1_run.upper[i] - 0.99 * unit[i], t1_run.upper[i] - 1.01 * unit[i]
        flags = reg.check_bounds(t1_run, near, 0.4, "")
        assert [f.check for f in flags] == ["bounds"] and f"bound of {name} (" in flags[0].message
        assert ask(reg.check_bounds, t1_run, clear) == []


def test_3d_gain_chance_and_stability_at_the_truth_and_away(t1_run):
    fine = t1_run.levels[-1].objective
    t1_run.measures = {}
    for check in (reg.check_gain, reg.check_chance, reg.check_stability):
        assert ask(check, t1_run, TRUTH3) == [], check.__name__
    assert t1_run.measures["ascent"] < 0 and t1_run.measures["chance"] > t1_run.params.check.chance
    assert t1_run.measures["stability"] < t1_run.params.check.stability
    off, start = TRUTH3 + np.r_[0.0, 0.0, 0.0, 3.0, 0.0, 0.0], t1_run.start
    t1_run.measures = {}
    try:
        t1_run.start = off  # started there: only the ascent one unit away can flag it
        assert ask(reg.check_gain, t1_run, off) == ["gain"]
    finally:
        t1_run.start = start
    by_hand = max((fine(off + s * u) - fine(off)) / fine(off) for u in np.diag(t1_run.scales) for s in (-1, 1))
    assert t1_run.measures["ascent"] == pytest.approx(by_hand, rel=1e-12)


def test_3d_chance_of_noise_is_one(t1_run):
    noise = t1_run.fixed.with_data(np.random.default_rng(5).normal(100.0, 30.0, t1_run.fixed.shape), name="noise")
    run = make_run(t1_run.fixed, noise)
    assert ask(reg.check_chance, run, TRUTH3) == ["chance"] and 0.5 < run.measures["chance"] < 2.0


def test_3d_label_measures_the_distance_to_a_label_maps_object_answer(t1_run):
    """As in 2D: a three-class label map of the KmeansTest T1 against the T1 moved by TRUTH3; its object's answer lies
    within 0.35 mm of the truth, so the test passes the truth and flags a result 8 mm off, measuring that distance."""
    t1 = t1_run.fixed
    obj = object_mask(t1)
    q = np.quantile(t1.data[obj], [1 / 3, 2 / 3])
    run = make_run(t1.with_data(np.where(obj, 1.0 + (t1.data > q[0]) + (t1.data > q[1]), 0.0)), t1_run.moving)
    for off, flagged in ((np.zeros(6), []), (np.r_[0.0, 0.0, 0.0, 8.0, 0.0, 0.0], ["label"])):
        run.measures = {}
        assert ask(reg.check_label, run, TRUTH3 + off) == flagged
        assert run.measures["label"] == pytest.approx(run.distance(TRUTH3 + off, TRUTH3), abs=0.35)


@pytest.mark.parametrize("d", [0.0, 6.0, 12.0])
def test_3d_content_is_the_lens_of_two_shifted_balls(d):
    """The volume two balls of radius R share with centres d apart, pi (4R + d)(2R - d)^2 / 12, over a ball's."""
    ball = ball_image()
    run = make_run(ball, ball)
    ask(reg.check_content, run, np.r_[0.0, 0.0, 0.0, d, 0.0, 0.0])
    radius = 14.0
    lens = math.pi * (4 * radius + d) * (2 * radius - d) ** 2 / 12 / (4 / 3 * math.pi * radius ** 3)
    assert run.measures["content"] == pytest.approx(lens, abs=0.03)


def test_3d_flatness_finds_the_rotations_a_ball_leaves_undetermined():
    """A ball looks the same under every rotation about its centre (the 3D default does not ask the test: asked
    here with the 2D threshold): the flattest direction is a rotation, with no translation in it."""
    run = make_run(ball_image(seed=0), ball_image(seed=1), min_flatness=0.1)
    flags = reg.check_flatness(run, np.zeros(6), run.levels[-1].objective(np.zeros(6)), "")
    assert [f.check for f in flags] == ["flatness"] and run.measures["flatness"] < 0.05
    assert "+0.00 tx, +0.00 ty, +0.00 tz" in flags[0].message


def test_3d_consistency_is_the_coarser_levels_drop_at_the_result(t1_run):
    t1_run.ends = [TRUTH3.copy() for _ in t1_run.levels]
    try:
        result = TRUTH3 + np.r_[0.0, 0.0, 0.0, 0.0, 6.0, 0.0]
        drops = [1.0 - lv.objective(result) / lv.objective(TRUTH3) for lv in t1_run.levels[:-1]
                 if t1_run.distance(result, TRUTH3) > 0.25 * lv.spacing]
        t1_run.measures = {}
        assert ask(reg.check_consistency, t1_run, result) == []  # 3D default: consistency 0, measured, not judged
        assert t1_run.measures["consistency"] == pytest.approx(max(drops), rel=1e-12) and max(drops) > 0
    finally:
        t1_run.ends = []


def test_3d_start_overlap_agreement_prominence_and_capture(t1_run):
    far = np.r_[0.0, 0.0, 0.0, 1000.0, 0.0, 0.0]
    assert ask(reg.check_start, t1_run, TRUTH3, "invalid_start") == ["start"]
    assert ask(reg.check_overlap, t1_run, far) == ["overlap"] and ask(reg.check_overlap, t1_run, TRUTH3) == []
    t1_run.measures = {}
    for check in (reg.check_agreement, reg.check_prominence, reg.check_capture):
        assert ask(check, t1_run, TRUTH3) == [], check.__name__
    assert t1_run.measures["agreement"] < 0.5 and t1_run.better is None
    assert t1_run.measures["prominence"] > t1_run.params.check.min_prominence
    wrong = TRUTH3 + np.r_[0.0, 0.0, 0.0, 0.0, 8.0, 0.0]
    assert ask(reg.check_agreement, t1_run, wrong) == ["agreement"] and t1_run.measures["agreement"] > 1.0
    wrong = TRUTH3 + np.r_[0.0, 0.0, math.radians(40.0), 0.0, 0.0, 0.0]  # 40 deg about z: another basin
    assert ask(reg.check_capture, t1_run, wrong) == ["capture"]
    assert t1_run.better is not None and t1_run.distance(t1_run.better[0], TRUTH3) < 1.0
    t1_run.better = None


@pytest.mark.parametrize("axis", [0, 1])
def test_3d_mirror_flags_a_volume_flipped_along_an_axis_and_not_the_unflipped_one(t1_run, axis):
    """3D (45th round): the x-mirrored moving volume's coarse search, turned by no or half a turn about y or z (the
    flips along x, z and y), against the pair's own search. A moved T1 flipped along array axis 0 or 1 scores far
    above its own best (the search's answer stands in for a registration's); the unflipped pair at its truth is quiet,
    its mirror scoring below it. The test does not need the refined coarsest level of 2D (``mirror_refine`` off)."""
    t1_run.measures = {}
    assert ask(reg.check_mirror, t1_run, TRUTH3) == [] and 0.3 < t1_run.measures["mirror"] < 1.0
    flipped = make_run(t1_run.fixed, t1_run.moving.with_data(np.flip(t1_run.moving.data, axis).copy()))
    answer = (grid := flipped.grid()).thetas[np.argmax(grid.values)]
    assert ask(reg.check_mirror, flipped, answer) == ["mirror"] and flipped.measures["mirror"] > 1.3
    assert not flipped.params.check.mirror_refine and flipped.params.check.mirror == pytest.approx(0.1)


def test_3d_mirrored_search_turns_half_about_the_moving_grids_own_axes(t1_run):
    """46th round: on a moving grid tilted 36 degrees about x (an oblique acquisition), the mirrored search's rotations
    are no turn and the half turns 2 u u^T - I about each of the moving grid's axes u (with the mirror along the
    grid's x: the flips along its z and y, and all three), not about the physical axes."""
    fixed = t1_run.fixed
    tilted = Image(fixed.data, fixed.spacing, fixed.origin, euler_matrix([math.radians(36.0), 0.0, 0.0]) @ fixed.direction)
    grid = make_run(fixed, tilted).coarse_search(mirrored=True)
    turns = {tuple(np.round(euler_matrix(t[:3]), 9).ravel()) for t in grid.thetas[: grid.n_coarse]}
    half = [np.eye(3)] + [2.0 * np.outer(u, u) - np.eye(3) for u in tilted.direction.T]
    assert turns == {tuple(np.round(m, 9).ravel()) for m in half} and len(turns) == 4


def test_3d_outline_gap_of_a_shifted_ball_and_its_flag():
    """A ball mask against itself (outline-only): shifted by s voxels (within the 4-voxel band) the outlines lie
    about s/2 apart (the volume between them, 2 pi R^2 s, over the area 4 pi R^2, to 10 % for the voxel surface):
    not flagged; shifted 12 voxels of 2 mm, more than ``outline_gap`` (6 mm): flagged."""
    ball = ball_image()
    run = make_run(ball, ball)
    assert run.outline_only
    for s in (0.0, 2.0):
        assert ask(reg.check_outline, run, np.r_[0.0, 0.0, 0.0, s, 0.0, 0.0]) == []
        assert run.measures["outline_gap"] == pytest.approx(s / 2, rel=0.1, abs=0.1)
    coarse = Image(ball.data, spacing=(2.0, 2.0, 2.0))
    run = make_run(coarse, coarse)
    assert ask(reg.check_outline, run, np.r_[0.0, 0.0, 0.0, 24.0, 0.0, 0.0]) == ["outline"]
    assert run.measures["outline_gap"] > run.params.check.outline_gap


def test_3d_overlap_bound_flags_a_result_whose_measure_rises_past_the_accepted_overlap(t1_run):
    """Off by default in 3D, asked here: the truth overlaps 13 %; at the first transform from it toward the start
    that overlaps 27 %, the measure with half the overlap accepted climbs to less than 25 % overlap."""
    t1 = t1_run.fixed
    extent = np.asarray(t1.size) * np.asarray(t1.spacing)
    truth = np.r_[0.0, 0.0, 0.2, 0.7 * extent[0], 0.25 * extent[1], 0.0]
    run = make_run(t1, moved(t1, RigidTransform(tuple(truth), tuple(t1.center))), overlap_bound=True)
    coarse = run.levels[0].objective
    assert coarse.overlap(truth) < 0.5 * run.params.metric.min_overlap + 0.01
    near = next(t for t in (truth + s * (run.start - truth) for s in np.linspace(0, 1, 21)) if coarse.overlap(t) >= 0.27)
    assert ask(reg.check_overlap_bound, run, near) == ["overlap_bound"]
    assert ask(reg.check_overlap_bound, make_run(t1_run.fixed, t1_run.moving, overlap_bound=True), TRUTH3) == []
