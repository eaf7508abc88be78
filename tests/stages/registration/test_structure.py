"""The interior-structure measure: its pieces against scipy.ndimage, silhouettes against images with insides."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from topomatch.stages.registration.image import Image, fill_holes, gaussian_blur
from topomatch.stages.registration.structure import interior_spread, interior_structure, outline_gap, outline_in_view


@pytest.mark.parametrize("shape", [(40, 50), (20, 25, 30)])
def test_gaussian_blur_and_fill_holes_equal_scipy(shape):
    rng = np.random.default_rng(0)
    data = rng.normal(size=shape)
    np.testing.assert_allclose(gaussian_blur(data, [1.0] * data.ndim, truncate=3.0),
                               ndimage.gaussian_filter(data, 1.0, mode="nearest", truncate=3), atol=1e-12)
    sigmas = [0.7, 0.0, 2.3][: data.ndim]
    np.testing.assert_allclose(gaussian_blur(data, sigmas), ndimage.gaussian_filter(data, sigmas, mode="nearest"),
                               atol=1e-12)
    mask = ndimage.binary_dilation(rng.uniform(size=shape) < 0.05, iterations=2)
    assert np.array_equal(fill_holes(mask), ndimage.binary_fill_holes(mask, structure=np.ones((3,) * len(shape))))
    ring = ~ndimage.binary_dilation(rng.uniform(size=shape) < 0.1, iterations=2)  # background with diagonal gaps
    assert np.array_equal(fill_holes(ring, cross=True), ndimage.binary_fill_holes(ring))  # scipy's default: 4- / 6-


@pytest.mark.parametrize("d", [2, 3])
def test_outline_gap_of_a_grown_or_shifted_ball(d):
    """A ball of radius R against the same ball grown by r (its edge r outside): the gap is r; against itself
    shifted by s (small): the area between the outlines over the outline's length, 2s/pi in 2D (lune area 4Rs over
    2 pi R), s/2 in 3D (2 pi R^2 s over 4 pi R^2); against itself, 0. Up to the pixel grid (the analysed copy is
    block-averaged by 2; the outline length is the indicator's total variation)."""
    from topomatch.stages.registration.transform import RigidTransform

    shape = (96, 100, 90)[:d]
    grids = np.meshgrid(*[np.arange(n) - (n - 1) / 2 for n in shape], indexing="ij")
    radius = np.sqrt(sum(g ** 2 for g in grids))
    fixed = Image(np.where(radius < 30, 100.0, 0.0))
    identity = RigidTransform.identity(fixed.center)
    assert outline_gap(fixed, fixed, identity) < 0.2
    for r in (2.0, 4.0):
        assert outline_gap(fixed, Image(np.where(radius < 30 + r, 100.0, 0.0)), identity) == pytest.approx(r, rel=0.15)
    s_ = 4.0
    shifted = RigidTransform(identity.parameters[: len(identity.parameters) - d] + (s_,) + (0.0,) * (d - 1),
                             fixed.center)
    expected = 2 * s_ / np.pi if d == 2 else s_ / 2
    assert outline_gap(fixed, fixed, shifted) == pytest.approx(expected, rel=0.15)


@pytest.mark.parametrize("d", [2, 3])
def test_a_silhouette_has_no_inside_an_image_with_a_pattern_has_one(d):
    """A uniform disc with 2 % noise scores ~0; the same disc with an inner ring as strong as its edge scores
    far more; ``interior_structure`` does not depend on the intensity scale."""
    shape = (64, 72, 60)[:d]
    grids = np.meshgrid(*[np.arange(n) - (n - 1) / 2 for n in shape], indexing="ij")
    radius = np.sqrt(sum(g ** 2 for g in grids))
    rng = np.random.default_rng(1)
    disc = np.where(radius < 22, 100.0, 0.0)
    pattern = disc - 50.0 * ((radius > 8) & (radius < 12))
    silhouette = interior_structure(Image(disc + rng.normal(0, 2.0, shape)))
    patterned = interior_structure(Image(pattern + rng.normal(0, 2.0, shape)))
    assert silhouette < 0.04 < 0.1 < patterned
    assert interior_structure(Image(7.0 * (pattern + 5.0))) == pytest.approx(interior_structure(Image(pattern)))


@pytest.mark.parametrize("d", [2, 3])
def test_interior_spread_of_two_level_and_one_level_objects(d):
    """A box whose halves are 1 and 2 on a background of 0 (the grids under 48 pixels: not block-averaged): Otsu
    keeps both halves, the core's q10, median, q90 are 1, 1.5, 2, so the spread is (2 - 1) / 1.5 = 2/3 whatever the
    scale; the box at one value scores 0, and so does a comb (one value, an outline full of concavities); a thresholded pattern (dark regions inside the
    object) is not judged (NaN), nor is an image whose content fills the grid."""
    shape = (40, 44, 36)[:d]
    inner = tuple(slice(5, n - 5) for n in shape)
    box = np.zeros(shape)
    box[inner] = 1.0
    halves = box.copy()
    halves[(slice(5, 5 + (shape[0] - 10) // 2),) + inner[1:]] = 2.0
    assert interior_spread(Image(halves)) == pytest.approx(2 / 3)
    assert interior_spread(Image(40.0 * halves + 7.0)) == pytest.approx(2 / 3)
    assert interior_spread(Image(box)) == 0.0
    comb = box.copy()
    for start in range(13, shape[1] - 5, 14):  # teeth 8 pixels wide, gaps of 6 (wider than the closing)
        comb[(slice(5, shape[0] - 15), slice(start, start + 6)) + inner[2:]] = 0.0
    assert interior_spread(Image(comb)) == 0.0
    holes = box.copy()
    holes[tuple(slice(10, n - 10) for n in shape)] = 0.0  # a dark region inside: not a mask
    assert np.isnan(interior_spread(Image(holes)))
    assert np.isnan(interior_spread(Image(np.ones(shape))))


@pytest.mark.parametrize("spacing", [(1.0, 1.0), (1.0, 1.0, 1.0), (0.5, 2.0, 3.0)])
def test_outline_in_view_of_a_box_clear_of_or_cut_by_the_border(spacing):
    """A box of a x b (x c) pixels: its whole boundary is outline while it is clear of the border; slid against
    one face of the grid, that face's area is cut, not outline; across the grid, both. Face areas
    in physical units (a face normal to an axis has the product of the other two spacings)."""
    dim = len(spacing)
    shape = (30, 40, 50)[:dim]
    sides = (10, 16, 22)[:dim]
    sp = np.asarray(spacing)[::-1]  # array axis order
    face = np.prod(sp) / sp
    boundary = [2 * face[a] * np.prod(sides) / sides[a] for a in range(dim)]  # both faces normal to axis a
    clear = np.zeros(shape)
    clear[tuple(slice(5, 5 + s) for s in sides)] = 100.0
    assert outline_in_view(Image(clear, spacing=spacing)) == pytest.approx(1.0)
    touching = np.zeros(shape)
    touching[tuple(slice(0, s) if a == 0 else slice(5, 5 + s) for a, s in enumerate(sides))] = 100.0
    assert outline_in_view(Image(touching, spacing=spacing)) == pytest.approx(1 - boundary[0] / 2 / sum(boundary))
    across = np.zeros(shape)  # the full extent of the first array axis: both of its faces cut
    across[tuple(slice(0, shape[0]) if a == 0 else slice(5, 5 + s) for a, s in enumerate(sides))] = 100.0
    walls = 2 * face[0] * np.prod(sides[1:])
    sides_across = [shape[0], *sides[1:]]
    total = sum(2 * face[a] * np.prod(sides_across) / sides_across[a] for a in range(dim))
    assert outline_in_view(Image(across, spacing=spacing)) == pytest.approx(1 - walls / total)


@pytest.mark.parametrize("d", [2, 3])
def test_outline_in_view_counts_what_a_cropped_partner_does_not_see(d):
    """Fourteenth round: a box clear of its grid's border, seen by a partner grid that ends halfway along the last
    array axis (identity transform): the faces past the partner's last pixel centre + 1/2 are cut. In 2D a 10 x 20
    box (rows x columns) whose columns 10-29 meet a partner of 20 columns: 10 of its 20 side faces and 20 of its 40
    top and bottom faces are seen, 30 of 60; in 3D the same box 6 slices deep: 200 of 400, 120 of 240 and 60 of
    120 faces normal to the three axes, 380 of 760."""
    from topomatch.stages.registration.transform import RigidTransform

    shape, box = ((40, 40), (slice(10, 20), slice(10, 30))) if d == 2 else \
        ((12, 40, 40), (slice(3, 9), slice(10, 20), slice(10, 30)))
    data = np.zeros(shape)
    data[box] = 100.0
    image, partner = Image(data), Image(np.zeros(shape[:-1] + (20,)))
    identity = RigidTransform.identity(tuple(image.center))
    assert outline_in_view(image) == pytest.approx(1.0)
    assert outline_in_view(image, partner, identity) == pytest.approx(30 / 60 if d == 2 else 380 / 760)


def test_a_silhouette_pair_is_flagged_when_its_levels_disagree_and_the_check_can_be_turned_off(pd_slice):
    """``outline_gap 0`` flags every silhouette pair; by default the flag follows the recorded measures (the
    outlines' gap at the result above ``outline_gap``, or the finest level left a coarser level's optimum by
    more than ``outline_drop``); ``min_structure 0`` turns the test off."""
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform

    silhouette = Image(np.where(fill_holes(pd_slice.data > 40), 100.0, 0.0), name="mask")
    moving = moved(silhouette, RigidTransform.euler2d(4.0, -3.0, 6.0, pd_slice.center))
    every = register(pd_slice, moving, RegisterParams.model_validate({"check": {"outline_gap": 0}}))
    assert "outline" in {f.check for f in every.flags} and not every.ok
    assert every.measures["structure_moving"] < 0.04 < every.measures["structure_fixed"]
    default = register(pd_slice, moving)
    drop, gap, c = default.measures.get("consistency", 0.0), default.measures["outline_gap"], RegisterParams().check
    view = default.measures["outline_view"]
    assert c.min_outline_view < view < 1  # the head touches the grid's border a little
    assert ("outline" in {f.check for f in default.flags}) == (drop > c.outline_drop or gap > c.outline_gap
                                                               or view < c.min_outline_view)
    off = register(pd_slice, moving, RegisterParams.model_validate({"check": {"min_structure": 0}}))
    assert "outline" not in {f.check for f in off.flags}


def _silhouette(image: Image) -> Image:
    """The object of ``image`` (its content closed, holes filled) as a uniform 100 on 0: a label map's outline."""
    from topomatch.stages.registration.structure import object_mask

    return image.with_data(np.where(object_mask(image), 100.0, 0.0), name="silhouette")


@pytest.mark.parametrize("metric", ["jt", "jr", "tmi"])
def test_an_outline_only_pair_is_registered_at_order_one_where_jt_jr_tmi_are_one_measure(pd_slice, metric):
    """PD slice against its own silhouette moved by a known T: the pair is outline-only, so the measure's order
    becomes ``metric.outline_alpha`` (1: JT with histogram weights, JR and TMI are all mutual information
    there, the same numbers to rounding) and the finest level is smoothed: T recovered to half a pixel (mean over
    every pixel), the order recorded, JT's agreement test not asked."""
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform, target_registration_error

    truth = RigidTransform.euler2d(6.0, -4.0, 5.0, pd_slice.center)
    moving = moved(_silhouette(pd_slice), truth)
    reg = register(pd_slice, moving, RegisterParams.model_validate({"metric": metric}))
    assert reg.measures["structure_moving"] < RegisterParams().check.min_structure
    assert reg.measures["outline_alpha"] == 1.0 and "agreement" not in reg.measures
    assert target_registration_error(reg.transform, truth, pd_slice.points()).mean() < 0.5
    if metric != "jt":
        jt = register(pd_slice, moving, RegisterParams.model_validate({"metric": "jt"}))
        np.testing.assert_allclose(reg.transform.parameters, jt.transform.parameters, atol=1e-8)


def test_either_detector_makes_a_pair_outline_only_and_both_off_make_it_ordinary(pd_slice):
    """PD slice against its own silhouette: with ``min_structure`` 0 the spread test alone finds the
    silhouette (its spread ~0, recorded) and the pair is registered at order 1 to half a pixel; with both
    tests off it is an ordinary pair (order 2, no outline measures)."""
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform, target_registration_error

    truth = RigidTransform.euler2d(-5.0, 3.0, -4.0, pd_slice.center)
    moving = moved(_silhouette(pd_slice), truth, noise=0.02, rng=np.random.default_rng(3))
    spread_only = register(pd_slice, moving, RegisterParams.model_validate({"check": {"min_structure": 0}}))
    assert spread_only.measures["spread_moving"] < 0.05 < spread_only.measures["spread_fixed"]
    assert spread_only.measures["outline_alpha"] == 1.0
    assert target_registration_error(spread_only.transform, truth, pd_slice.points()).mean() < 0.5
    off = register(pd_slice, moving, RegisterParams.model_validate({"check": {"min_structure": 0, "min_spread": 0}}))
    assert not any(k.startswith(("spread", "structure", "outline")) for k in off.measures)


def test_an_ordinary_pair_ignores_the_outline_settings_and_level_smoothing_blurs_the_level(pd_slice):
    """T1 against PD has structure inside: the outline settings change nothing (bit-identical results with them
    off); a level's ``smoothing`` is a Gaussian of that many of its own pixels on both block-averaged images."""
    from topomatch.stages.registration.io import read_image
    from topomatch.stages.registration.params import RegisterParams, for_dimension
    from topomatch.stages.registration.register import _Run, register

    t1_slice = read_image(pd_slice.source.replace("BrainProtonDensitySlice", "BrainT1Slice"))
    base = register(pd_slice, t1_slice)
    assert "outline_alpha" not in base.measures
    off = register(pd_slice, t1_slice, RegisterParams.model_validate({"metric": {"outline_alpha": None},
                                                                      "outline_smoothing": 0}))
    assert np.array_equal(base.transform.parameters, off.transform.parameters) and base.value == off.value
    params = for_dimension(RegisterParams(), 2)
    schedule = [lv.model_copy(update={"smoothing": 1.5}) for lv in params.schedule]
    run = _Run(pd_slice, t1_slice, params.model_copy(update={"schedule": schedule}), None, None)
    compared = 0
    for level, spec in zip(run.levels, schedule):
        for got, image in zip(level.images[:2], (pd_slice, t1_slice)):
            small = image.shrink_to(spec.spacing, 8)
            if got.spacing == small.spacing:  # a level with too few samples is measured on a finer grid
                np.testing.assert_allclose(got.data, gaussian_blur(small.data, [1.5, 1.5]), atol=1e-12)
                compared += 1
    assert compared >= 4


@pytest.mark.parametrize("d", [2, 3])
def test_plateau_share_of_a_block_label_is_its_inner_fraction_and_of_noise_zero(d):
    """A block of n pixels a side at one label on 0 is its own object; a pixel of it equals its next neighbour along
    every axis unless it lies on the block's last row, column (or slice): ((n - 1) / n)^d of them. With noise: 0."""
    from topomatch.stages.registration.structure import plateau_share

    n, data = 20, np.zeros((40,) * d)
    data[(slice(10, 10 + n),) * d] = 7.0
    assert plateau_share(Image(data)) == pytest.approx(((n - 1) / n) ** d, abs=1e-12)
    assert plateau_share(Image(data + np.random.default_rng(0).normal(0, 0.01, data.shape))) == 0.0


@pytest.mark.parametrize("d", [2, 3])
def test_distinct_levels_counts_a_label_map_and_stops_above_the_limit(d):
    """A label map of 3 values over a strided subset holds 3; a noisy image counts as ``limit + 1``."""
    from topomatch.stages.registration.structure import distinct_levels

    shape = (64, 80) if d == 2 else (24, 30, 36)
    labels = np.indices(shape).sum(axis=0) % 3
    assert distinct_levels(Image(labels.astype(np.float64)), 16) == 3
    assert distinct_levels(Image(labels.astype(np.float64)), 2) == 3  # counted up to limit + 1
    noisy = labels + np.random.default_rng(0).normal(0, 0.01, shape)
    assert distinct_levels(Image(noisy), 16) == 17


def test_a_thresholded_image_with_structure_inside_is_measured_at_order_one_but_not_flagged_as_outline(pd_slice):
    """PD slice against itself thresholded (binary, with structure inside: not outline-only) moved by a known T:
    the pair is discrete (2 levels, recorded), measured at ``outline_alpha`` with the finest level smoothed, not
    asked the outline test, T recovered to half a pixel; with ``discrete_levels`` 0 it is an ordinary pair."""
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform, target_registration_error

    truth = RigidTransform.euler2d(7.0, -5.0, 4.0, pd_slice.center)
    shifted = moved(pd_slice, truth)  # thresholded after the move, as a user's mask is: exactly two levels
    inside = shifted.data[shifted.data > 0.2 * shifted.data.max()]
    moving = shifted.with_data((shifted.data > np.percentile(inside, 50)).astype(np.float64))
    reg = register(pd_slice, moving)
    assert reg.measures["discrete_levels"] == 2 and reg.measures["outline_alpha"] == 1.0
    assert reg.measures["structure_moving"] > RegisterParams().check.min_structure and "outline_gap" not in reg.measures
    assert target_registration_error(reg.transform, truth, pd_slice.points()).mean() < 0.5
    off = register(pd_slice, moving, RegisterParams.model_validate({"metric": {"discrete_levels": 0}}))
    assert "discrete_levels" not in off.measures and "outline_alpha" not in off.measures


@pytest.mark.parametrize("d", [2, 3])
def test_the_finest_level_of_a_label_map_is_smoothed_by_label_smoothing_and_of_a_mask_by_outline_smoothing(d, pd_slice):
    """Thirty-sixth round: a discrete pair's finest level is smoothed by ``outline_smoothing`` (1 pixel) when its
    discrete image has two levels (a thresholded mask: the step becomes a ramp) and by ``label_smoothing`` when it has
    three labels or more (default 1 pixel in 2D, 0 in 3D: a blend of two labels falls on a third's value); set
    explicitly, ``label_smoothing`` is used in either dimension. Thirty-seventh round: a label map's finest level takes
    ``label_samples`` times its samples (2D 1, 3D 4), a mask's its own. Both measured at ``outline_alpha``. 2D: the PD slice;
    3D: KmeansTest at 4 x 4 x 3 mm; each against a three-class label map and a binary mask of itself."""
    from tests_paths import ITK_DIR
    from topomatch.stages.registration.io import read_image
    from topomatch.stages.registration.params import RegisterParams, for_dimension
    from topomatch.stages.registration.register import MIN_LEVEL_VOXELS, _Run

    fixed = pd_slice if d == 2 else read_image(ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz").shrink((2, 2, 1))
    inside = fixed.data > 0.2 * fixed.data.max()
    q = np.quantile(fixed.data[inside], [1 / 3, 2 / 3])
    labels = np.where(inside, 1.0 + (fixed.data > q[0]) + (fixed.data > q[1]), 0.0)
    default, times = (1.0, 1) if d == 2 else (0.0, 4)
    for moving, given, sigma, factor in ((labels, {}, default, times), ((labels == 3).astype(float), {}, 1.0, 1),
                                         (labels, {"label_smoothing": 0.5, "label_samples": 2}, 0.5, 2),
                                         (labels, {"label_smoothing": 0}, 0.0, times)):
        params = for_dimension(RegisterParams.model_validate(given), d)
        run = _Run(fixed, fixed.with_data(moving), params, None, None)
        assert not run.outline_only and run.levels_count == len(np.unique(moving))
        assert run.metric.alpha == params.metric.outline_alpha and params.outline_smoothing == 1.0
        assert run.levels[-1].spec.samples == factor * params.schedule[-1].samples
        assert [lv.spec for lv in run.levels[:-1]] == params.schedule[:-1]  # the coarser levels as scheduled
        for got, image in zip(run.levels[-1].images[:2], (fixed, fixed.with_data(moving))):
            small = image.shrink_to(params.schedule[-1].spacing, MIN_LEVEL_VOXELS)
            expected = gaussian_blur(small.data, [sigma] * d) if sigma else small.data
            np.testing.assert_allclose(got.data, expected, atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_two_class_residual_of_a_grid_filling_two_level_image_is_its_noise(d):
    """An object that fills the grid (the dark part a corner, 44 %, or a one-pixel slab at a face: no outline to judge,
    both other measures NaN): at two levels 0 / 1 the measure is 0; with Gaussian noise of deviation s it is s^2
    (the classes' variance over their contrast 1 squared) whatever the dark fraction, to sampling error (dividing
    by the total variance instead gave s^2 / (p (1 - p) + s^2): 0.03 at 1.4 % dark, like an image with an inside); a
    linear ramp added inside (an image with an inside) raises it far above; an object inside a background is judged
    by the other two tests (NaN here)."""
    from topomatch.stages.registration.structure import two_class_residual

    shape = (60, 70) if d == 2 else (30, 34, 38)
    grid = np.indices(shape)
    s = 0.02
    corner = np.all(grid < (np.array(shape) * 0.45 ** (1 / d)).astype(int).reshape((d,) + (1,) * d), axis=0)
    for dark in (corner, grid[-1] == 0):  # 44 % dark, or a one-pixel slab: 1.4 % (2D), 2.6 % (3D)
        two = np.where(dark, 0.0, 1.0)
        assert np.isnan(interior_structure(Image(two))) and np.isnan(interior_spread(Image(two)))
        assert two_class_residual(Image(two)) == 0.0
        noisy = two + np.random.default_rng(1).normal(0, s, shape)
        assert two_class_residual(Image(noisy)) == pytest.approx(s ** 2, rel=0.15)
        ramp = two + np.where(dark, 0.0, 1.0 * grid[-1] / shape[-1])
        assert two_class_residual(Image(ramp)) > 25 * s ** 2
    ball = (np.sqrt(((grid - np.array(shape).reshape((d,) + (1,) * d) / 2) ** 2).sum(axis=0)) < min(shape) / 3)
    assert np.isnan(two_class_residual(Image(ball.astype(np.float64))))


def _class_ratio(data: np.ndarray) -> float:
    """The two Otsu classes' worse variance over their squared contrast (the residual without the plateau rule)."""
    from topomatch.stages.registration.image import otsu_threshold

    upper = data > otsu_threshold(data)
    return max(data[upper].var(), data[~upper].var()) / (data[upper].mean() - data[~upper].mean()) ** 2


@pytest.mark.parametrize("d", [2, 3])
def test_an_image_mostly_at_its_two_extremes_with_a_ramp_between_has_no_residual(d):
    """Twenty-third round. A grid-filling image by the distance from a corner (an object with no outline to judge):
    the nearest 20 % of the pixels at 0, then a ramp of distinct values, the rest at 1. With the ramp over 40 % of
    the pixels (60 % at 0 or 1) the residual is 0 (two plateaus and a ramp: a soft mask); over 60 % (40 % at the
    extremes), or with the ramp at four label values (a label map, no ramp), it is the classes' variance ratio,
    computed here from its definition."""
    from topomatch.stages.registration.structure import two_class_residual

    shape = (60, 70) if d == 2 else (30, 34, 38)
    distance = np.sqrt((np.indices(shape, dtype=np.float64) ** 2).sum(axis=0))
    rank = np.argsort(np.argsort(distance, axis=None, kind="stable")).reshape(shape) / distance.size  # in [0, 1)

    def image(ramp: float, levels: int = 0) -> np.ndarray:
        r = (rank - 0.2) / ramp
        r = np.round(r * levels) / levels if levels else r
        return np.where(rank < 0.2, 0.0, np.where(rank < 0.2 + ramp, r, 1.0))

    for data, plateau in ((image(0.4), True), (image(0.6), False), (image(0.4, levels=4), False)):
        assert np.isnan(interior_structure(Image(data))) and np.isnan(interior_spread(Image(data)))
        expected = 0.0 if plateau else _class_ratio(data)
        assert expected == 0.0 or expected > 0.01
        assert two_class_residual(Image(data)) == pytest.approx(expected, rel=1e-9)


def test_a_tight_soft_mask_is_outline_only_by_its_plateaus_and_with_noise_by_nothing(pd_slice):
    """The tight PD crop below against its silhouette blurred by a Gaussian of 2 pixels (a soft mask, no noise): its
    ramp gives the Otsu classes a variance ratio of ~0.018, nine times ``min_residual``, so before the twenty-third
    round the pair was read as an image; at 0 or 1 on 83 % of its pixels, its residual is 0 and the pair outline-only.
    With 2 % noise no pixel sits at an extreme, and the ratio (ramp and noise) reads it as an image, as before."""
    from topomatch.stages.registration.params import RegisterParams, for_dimension
    from topomatch.stages.registration.register import _Run
    from topomatch.stages.registration.structure import object_mask

    rows, cols = pd_slice.data.shape
    window = (slice(0, rows // 2), slice(cols // 4, 3 * cols // 4))
    fixed = pd_slice.with_data(pd_slice.data[window].copy())
    soft = gaussian_blur(object_mask(pd_slice)[window].astype(np.float64), [2.0, 2.0])
    params = for_dimension(RegisterParams(), 2)
    assert _class_ratio(soft) > 5 * params.check.min_residual
    run = _Run(fixed, fixed.with_data(soft), params, None, None)
    assert run.structures["residual_moving"] == 0.0 and run.outline_only
    noisy = soft + np.random.default_rng(0).normal(0, 0.02, soft.shape)
    run = _Run(fixed, fixed.with_data(noisy), params, None, None)
    assert run.structures["residual_moving"] > params.check.min_residual and not run.outline_only


def test_a_tight_silhouette_is_outline_only_by_its_residual_and_the_test_can_be_turned_off(pd_slice):
    """The PD slice cropped to its upper middle (the head fills the grid) against the silhouette of that crop, 2 %
    noise: structure and spread cannot judge the silhouette (NaN), its two-class residual (~1e-3) makes the pair
    outline-only; with ``min_residual`` 0 it is an ordinary pair."""
    from topomatch.stages.registration.params import RegisterParams, for_dimension
    from topomatch.stages.registration.register import _Run
    from topomatch.stages.registration.structure import object_mask

    rows, cols = pd_slice.data.shape
    window = (slice(0, rows // 2), slice(cols // 4, 3 * cols // 4))  # the top of the head, 13 % of it outside
    fixed = pd_slice.with_data(pd_slice.data[window].copy())
    mask = object_mask(pd_slice)[window].astype(np.float64)
    moving = fixed.with_data(mask + np.random.default_rng(0).normal(0, 0.02, mask.shape))
    params = for_dimension(RegisterParams(), 2)
    run = _Run(fixed, moving, params, None, None)
    assert "structure_moving" not in run.structures and "spread_moving" not in run.structures
    assert run.structures["residual_moving"] < params.check.min_residual and run.outline_only
    off = params.model_copy(update={"check": params.check.model_copy(update={"min_residual": 0.0})})
    assert not _Run(fixed, moving, off, None, None).outline_only


@pytest.mark.parametrize("d", [2, 3])
def test_interior_structure_equals_its_definition_computed_with_scipy(pd_slice, d):
    """On a real image (the PD slice; the KmeansTest T1 volume), the value is its definition computed with
    scipy.ndimage: the copy block-averaged by 2 along axes of 48 pixels or more, its object (``object_mask``,
    tested on its own), the outline band (the object grown by 2 px, a square box, and its background grown by 2),
    the interior (the object less its background grown by 3), and the mean gradient magnitude of the copy blurred
    by 1 px (truncated at 3) inside over its mean on the band."""
    from tests_paths import ITK_DIR
    from topomatch.stages.registration.io import read_image
    from topomatch.stages.registration.structure import analysed_copy, object_mask

    image = pd_slice if d == 2 else read_image(ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz")
    small = analysed_copy(image)
    factors = [2 if n >= 48 else 1 for n in image.data.shape]
    cropped = image.data[tuple(slice(0, n - n % f) for n, f in zip(image.data.shape, factors))]
    by_hand = cropped.reshape([x for n, f in zip(cropped.shape, factors) for x in (n // f, f)]).mean(
        axis=tuple(range(1, 2 * d, 2)))
    np.testing.assert_allclose(small.data, by_hand, rtol=1e-12)
    obj = object_mask(small)
    box = lambda r: np.ones((2 * r + 1,) * d, dtype=bool)  # noqa: E731
    band = ndimage.binary_dilation(obj, box(2)) & ndimage.binary_dilation(~obj, box(2))
    inside = ~ndimage.binary_dilation(~obj, box(3))
    magnitude = np.sqrt(sum(g ** 2 for g in np.gradient(ndimage.gaussian_filter(small.data, 1.0, mode="nearest",
                                                                                 truncate=3.0))))
    assert band.sum() > 100 and inside.sum() > 100
    assert interior_structure(image) == pytest.approx(magnitude[inside].mean() / magnitude[band].mean(), rel=1e-9)


@pytest.mark.parametrize("d", [2, 3])
def test_a_pair_little_spread_inside_its_object_is_measured_at_order_one_below_the_threshold_only(d):
    """KmeansTest's T1 against a copy saturated at its content's 10th percentile (2 % noise: structure inside, so not
    outline-only) moved by a known T, in 3D and as its middle axial section. With ``metric.outline_spread`` above the
    copy's interior spread, JT is measured at ``metric.outline_alpha`` (recorded; the same parameters as asking for
    alpha 1; no agreement test) and T is recovered to a voxel; at the default, which that spread exceeds, the pair
    is ordinary: bit-identical to the setting off (fortieth round)."""
    from pathlib import Path

    from topomatch.stages.registration.image import foreground_mask
    from topomatch.stages.registration.io import read_image
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.params import RegisterParams
    from topomatch.stages.registration.register import register
    from topomatch.stages.registration.transform import RigidTransform, target_registration_error

    volume = read_image(str(Path(__file__).resolve().parents[3] / "data/images/itk/KmeansTest_T1UCharRaw.nii.gz"))
    fixed = volume if d == 3 else Image(volume.data[volume.shape[0] // 2], spacing=volume.spacing[:2])
    level = np.percentile(fixed.data[foreground_mask(fixed)], 10)
    rng = np.random.default_rng(4)
    saturated = fixed.with_data(np.minimum(fixed.data, level) + rng.normal(0.0, 0.02 * level, fixed.shape))
    truth = RigidTransform.from_degrees((4.0,) * (1 if d == 2 else 3) + (3.0, -2.0, 4.0)[:d], fixed.center)
    moving = moved(saturated, truth)
    spread = interior_spread(moving)
    assert RegisterParams().check.min_spread < RegisterParams().metric.outline_spread < spread < 0.3

    def run(**metric):
        return register(fixed, moving, RegisterParams.model_validate({"metric": metric}))

    low = run(outline_spread=0.3)
    assert low.measures["outline_alpha"] == 1.0 and "agreement" not in low.measures and low.ok
    assert np.array_equal(low.transform.parameters, run(outline_spread=0.3, alpha=1.0).transform.parameters)
    assert target_registration_error(low.transform, truth, fixed.points()).mean() < max(fixed.spacing)
    default, off = run(), run(outline_spread=0.0)
    assert "outline_alpha" not in default.measures and "agreement" in default.measures
    assert np.array_equal(default.transform.parameters, off.transform.parameters) and default.value == off.value
