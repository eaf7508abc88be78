"""Rigid transforms in ITK's convention: composition, inverse, centres, the thesis's R, TRE."""

from __future__ import annotations

import math

import numpy as np

from topomatch.stages.registration.transform import (RigidTransform, from_thesis, grid_points, rotation_matrix,
                                           target_registration_error)


def test_rotation_matrix_sign_convention():
    R = rotation_matrix(90.0)
    np.testing.assert_allclose(R, [[0, -1], [1, 0]], atol=1e-15)
    # x = (col, row) with rows pointing down: +90 deg takes the +col direction to +row (clockwise on screen)
    np.testing.assert_allclose(R @ [1.0, 0.0], [0.0, 1.0], atol=1e-15)


def test_apply_matches_definition_and_homogeneous_matrix():
    T = RigidTransform(3.0, -2.0, 30.0, (10.0, 5.0))
    pts = np.array([[10.0, 5.0], [0.0, 0.0], [12.5, -4.0]])
    expected = (pts - [10, 5]) @ rotation_matrix(30).T + [10, 5] + [3, -2]
    np.testing.assert_allclose(T.apply(pts), expected)
    M = T.homogeneous()
    np.testing.assert_allclose((M @ np.column_stack([pts, np.ones(3)]).T).T[:, :2], expected)
    np.testing.assert_allclose(T.apply(pts[:1]), [[13.0, 3.0]])  # the centre moves by t only


def test_inverse_composes_to_identity():
    T = RigidTransform(7.5, 11.0, -23.0, (40.0, 33.0))
    pts = np.random.default_rng(0).uniform(-50, 100, size=(20, 2))
    np.testing.assert_allclose(T.inverse().apply(T.apply(pts)), pts, atol=1e-12)
    np.testing.assert_allclose(T.apply(T.inverse().apply(pts)), pts, atol=1e-12)


def test_with_center_is_the_same_map():
    T = RigidTransform(2.0, 3.0, 17.0, (0.0, 0.0))
    U = T.with_center((50.0, 20.0))
    pts = np.random.default_rng(1).uniform(-10, 60, size=(10, 2))
    np.testing.assert_allclose(U.apply(pts), T.apply(pts), atol=1e-12)
    assert U.center == (50.0, 20.0) and U.angle == T.angle


def test_thesis_rotation_is_itk_rotation_of_the_opposite_angle():
    a = 12.0
    thesis_R = np.array([[math.cos(math.radians(a)), math.sin(math.radians(a))],
                         [-math.sin(math.radians(a)), math.cos(math.radians(a))]])
    np.testing.assert_allclose(thesis_R, rotation_matrix(-a))
    T = from_thesis(4.0, 5.0, a, (9.0, 9.0))
    assert (T.tx, T.ty, T.angle) == (4.0, 5.0, -a)
    assert T.to_thesis() == (4.0, 5.0, a)


def test_for_image_uses_the_pixel_centre_convention():
    T = RigidTransform.for_image((217, 181), 1.0, 2.0, 3.0)
    assert T.center == (90.0, 108.0)


def test_tre_of_a_translation_is_its_length_everywhere():
    a = RigidTransform.for_image((20, 30), 3.0, 4.0, 0.0)
    b = RigidTransform.for_image((20, 30))
    tre = target_registration_error(a, b, (20, 30))
    np.testing.assert_allclose(tre, 5.0)


def test_tre_of_a_rotation_about_the_centre():
    shape = (41, 61)
    a = RigidTransform.for_image(shape, angle=10.0)
    b = RigidTransform.for_image(shape)
    pts = grid_points(shape) - a.center
    expected = 2 * math.sin(math.radians(5.0)) * np.linalg.norm(pts, axis=1)  # chord of a 10-degree arc
    np.testing.assert_allclose(target_registration_error(a, b, shape), expected, atol=1e-12)
