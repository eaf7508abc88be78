"""Exact answers for the registration folder's small public functions that the larger tests only reach through a
stage: the known transform of a config's ``truth``, random misalignments, the contrast map, the coarse search's
spacing, the angle count, and the overlays' display window and checkerboard."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from topomatch.pipeline.contract import StageError
from topomatch.stages.registration.evaluate import truth_transform
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.misalign import random_transform, tissue_contrast
from topomatch.stages.registration.reports import checkerboard, display_window, windowed
from topomatch.stages.registration.search import SEARCH_SIDE, search_spacing
from topomatch.stages.registration.transform import euler_matrix, n_angles


def test_n_angles_is_one_in_2d_and_three_in_3d():
    assert (n_angles(2), n_angles(3)) == (1, 3)


@pytest.mark.parametrize("d", [2, 3])
def test_truth_about_another_centre_maps_points_as_written_by_hand(d):
    """``truth`` (degrees, physical units) about its own centre c0, rewritten about the fixed grid's centre: every
    point maps to R (p - c0) + c0 + t, R the Euler matrix of the angles."""
    fixed = Image(np.zeros((12, 16) if d == 2 else (6, 10, 14)))
    angles, t, c0 = ([20.0], [3.0, -2.0], [1.0, 2.0]) if d == 2 else ([10.0, -5.0, 30.0], [1.0, 2.0, -3.0],
                                                                       [0.5, 4.0, 2.0])
    names = ("angle", "tx", "ty") if d == 2 else ("angle_x", "angle_y", "angle_z", "tx", "ty", "tz")
    T = truth_transform({**dict(zip(names, angles + t)), "center": c0}, fixed)
    assert T.center == tuple(fixed.center)
    p = np.random.default_rng(0).uniform(-10, 10, size=(7, d))
    R = euler_matrix(np.radians(angles))
    np.testing.assert_allclose(T.apply(p), (p - c0) @ R.T + c0 + t, atol=1e-12)
    missing = truth_transform({names[-1]: 4.0}, fixed)  # the others default to 0, about the fixed centre
    np.testing.assert_allclose(missing.apply(p), p + np.eye(d)[-1] * 4.0, atol=1e-12)
    with pytest.raises(StageError, match="unknown keys"):
        truth_transform({"scale": 2.0}, fixed)
    with pytest.raises(StageError, match="must be numbers"):
        truth_transform({names[0]: "ten"}, fixed)
    with pytest.raises(StageError, match="known transform"):
        truth_transform(None, fixed)


@pytest.mark.parametrize("d", [2, 3])
def test_random_transforms_stay_in_their_bounds_and_repeat_with_their_seed(d):
    center = tuple(float(v) for v in range(1, d + 1))
    draws = [random_transform(np.random.default_rng(s), center, max_angle=15.0, max_translation=7.0)
             for s in range(200)]
    angles = np.array([t.angles_deg for t in draws])
    moves = np.array([t.translation for t in draws])
    assert angles.shape == (200, n_angles(d)) and moves.shape == (200, d)
    assert np.abs(angles).max() <= 15.0 and np.abs(moves).max() <= 7.0
    assert np.abs(angles).max() > 13.0 and np.abs(moves).max() > 6.5  # the bounds are reached, not shrunk
    assert all(t.center == center for t in draws)
    again = random_transform(np.random.default_rng(3), center, max_angle=15.0, max_translation=7.0)
    assert again.parameters == draws[3].parameters


def test_tissue_contrast_takes_its_levels_at_its_knots():
    """A background of 0 and 501 foreground values 90 ... 100 (their quartiles are pixels): the map is ``levels[0]``
    at the minimum, ``levels[3]``, ``[4]``, ``[5]`` at the foreground's quartiles and ``levels[7]`` at the maximum,
    times the foreground's maximum, and linear between."""
    fg = np.linspace(90.0, 100.0, 501)
    data = np.concatenate([np.zeros(499), fg])
    levels = [0.0, 0.05, 0.1, 0.8, 0.6, 0.4, 0.3, 0.2]
    out = tissue_contrast(data, levels)
    assert out[0] == pytest.approx(levels[0] * 100.0)
    for q, k in ((0.25, 3), (0.5, 4), (0.75, 5)):
        assert out[499 + round(q * 500)] == pytest.approx(levels[k] * 100.0, abs=1e-6)
    assert out[-1] == pytest.approx(levels[7] * 100.0, abs=1e-5)
    between = 499 + 190  # between the 25th (index 125) and 50th (250) percentiles of the foreground
    assert out[between] == pytest.approx(np.interp(fg[190], [fg[125], fg[250]], [80.0, 60.0]), abs=1e-6)


def test_search_spacing_brings_the_smaller_extent_to_the_search_side():
    a = Image(np.zeros((50, 100)))                     # 100 x 50 units
    b = Image(np.zeros((40, 40)), spacing=(2.0, 2.0))  # 80 x 80 units
    assert search_spacing([a, b]) == pytest.approx(50.0 / SEARCH_SIDE)
    c = Image(np.zeros((8, 30, 30)), spacing=(1.0, 1.0, 3.0))  # 30 x 30 x 24 units
    assert search_spacing([c]) == pytest.approx(24.0 / SEARCH_SIDE)
    region = np.zeros((50, 100), dtype=bool)
    region[10:30, 20:95] = True  # 75 x 20 units of a's grid: the first image's extent is the region's box
    assert search_spacing([a, b], region) == pytest.approx(20.0 / SEARCH_SIDE)
    assert search_spacing([a, b], np.zeros_like(region)) == pytest.approx(50.0 / SEARCH_SIDE)  # empty: the grid's
    box = np.zeros((8, 30, 30), dtype=bool)
    box[2:5, 3:4, 10:28] = True  # (k, j, i): 18 x 1 x 9 units of c's grid (z spacing 3)
    assert search_spacing([c], box) == pytest.approx(1.0 / SEARCH_SIDE)
    box[2:5, 3:23, 10:28] = True  # 18 x 20 x 9 units
    assert search_spacing([c], box) == pytest.approx(9.0 / SEARCH_SIDE)


def test_display_window_and_checkerboard():
    """The window is the 0.5th and 99.5th percentiles; the checkerboard alternates tiles of min(H, W) // tiles
    pixels, each image in its own window."""
    a = np.arange(64.0).reshape(8, 8)
    b = 100.0 + a[::-1]
    assert display_window(a) == pytest.approx(tuple(np.percentile(a, (0.5, 99.5))))
    board = checkerboard(a, b, tiles=4)  # 2-pixel tiles
    wa, wb = windowed(a, *display_window(a)), windowed(b, *display_window(b))
    rows, cols = np.mgrid[0:8, 0:8]
    first = ((rows // 2) + (cols // 2)) % 2 == 0
    np.testing.assert_array_equal(board[first], wa[first])
    np.testing.assert_array_equal(board[~first], wb[~first])
    assert windowed(np.array([3.0, 5.0]), 4.0, 4.0).tolist() == [0.0, 1.0]  # empty window: x - lo, clipped
    assert math.isclose(float(windowed(np.array([7.0]), 4.0, 10.0)[0]), 0.5)


def test_histogram_threads_follow_omp_num_threads_else_the_cpus_up_to_four(monkeypatch):
    from topomatch.stages.registration.histogram import histogram_threads

    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert histogram_threads() == 3
    for unset in ("", "0", "two"):
        monkeypatch.setenv("OMP_NUM_THREADS", unset)
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        assert histogram_threads() == max(1, min(4, cpus))


@pytest.mark.parametrize("bad, message", [
    (np.zeros((0, 5)), "empty"), (np.array([["a"] * 5] * 5), "not numbers"), (np.ones((5, 5)) * (1 + 1j), "complex"),
    (np.where(np.eye(5) > 0, np.nan, 1.0), "5 of 25 pixels are NaN"), (np.full((5, 5), 2.0), "constant"),
    (np.arange(15.0).reshape(3, 5), "too small"), (np.array([[-1e308, 1e308] * 3] * 5), "double precision"),
    (np.arange(25.0).reshape(5, 5) * 1e300, "overflow double precision")])
def test_check_pixels_names_the_file_and_the_problem(bad, message):
    from topomatch.pipeline.errors import InputError
    from topomatch.stages.registration.io import check_pixels

    with pytest.raises(InputError, match=f"in.png.*{message}"):
        check_pixels(bad, "in.png")
    good = check_pixels(np.arange(25, dtype=np.uint8).reshape(5, 5), "in.png")
    assert good.dtype == np.float64 and good[4, 4] == 24.0


@pytest.mark.parametrize("d", [2, 3])
def test_scaled_image_and_transform_multiply_physical_coordinates(d):
    from topomatch.stages.registration.transform import RigidTransform

    rng = np.random.default_rng(d)
    direction = np.linalg.qr(rng.normal(size=(d, d)))[0]
    image = Image(rng.uniform(size=(4,) * d), tuple(rng.uniform(0.5, 2, d)), tuple(rng.normal(size=d)), direction)
    big = image.scaled(2.5)
    np.testing.assert_allclose(big.points(), 2.5 * image.points(), atol=1e-12)
    assert big.data is image.data and np.array_equal(big.direction, image.direction)
    t = RigidTransform(tuple(rng.normal(size=3 * d - 3)), tuple(rng.normal(size=d)))
    p = rng.normal(size=(6, d))
    np.testing.assert_allclose(t.scaled(2.5).apply(2.5 * p), 2.5 * t.apply(p), atol=1e-12)
    assert t.scaled(2.5).angles == t.angles
