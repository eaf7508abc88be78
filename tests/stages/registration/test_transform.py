"""The rigid transform, 2D and 3D: ITK's Euler2D / Euler3D conventions, composition, centres, the thesis's R, TRE."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.stages.registration.transform import (RigidTransform, euler_angles, euler_matrix, from_thesis,
                                                     target_registration_error)

SimpleITK = pytest.importorskip("SimpleITK")


def _random(rng, d):
    k = 1 if d == 2 else 3
    return RigidTransform(tuple(rng.uniform(-0.6, 0.6, k)) + tuple(rng.uniform(-20, 20, d)),
                          tuple(rng.uniform(-50, 50, d)))


def test_2d_rotation_sign_convention():
    R = euler_matrix([math.pi / 2])
    np.testing.assert_allclose(R, [[0, -1], [1, 0]], atol=1e-15)
    # x = (col, row) with rows pointing down: +90 deg takes the +col direction to +row (clockwise on screen)
    np.testing.assert_allclose(R @ [1.0, 0.0], [0.0, 1.0], atol=1e-15)
    t = RigidTransform.euler2d(3.0, -2.0, 30.0, (10.0, 5.0))
    assert t.parameters == (math.radians(30.0), 3.0, -2.0) and (t.tx, t.ty, t.angle) == pytest.approx((3.0, -2.0, 30.0))
    assert t.names == ("angle", "tx", "ty")


@pytest.mark.parametrize("d", [2, 3])
def test_points_and_matrix_equal_simpleitk(d):
    rng = np.random.default_rng(3)
    for _ in range(5):
        t = _random(rng, d)
        e = t.to_sitk()
        assert e.GetName() == ("Euler2DTransform" if d == 2 else "Euler3DTransform")
        pts = rng.normal(0, 60, (4, d))
        np.testing.assert_allclose(t.apply(pts), [e.TransformPoint(tuple(p)) for p in pts], atol=1e-10)
        M = t.matrix()
        assert M.shape == (d + 1, d + 1)
        np.testing.assert_allclose((M @ np.c_[pts, np.ones(4)].T).T[:, :d], t.apply(pts), atol=1e-10)
        np.testing.assert_allclose(euler_angles(t.rotation), t.angles, atol=1e-12)
        back = RigidTransform.from_sitk(e)
        np.testing.assert_allclose(back.parameters, t.parameters, atol=1e-12)


def test_3d_rotation_is_rz_rx_ry():
    ax, ay, az = 0.3, -0.2, 0.5
    c, s = math.cos, math.sin
    Rx = [[1, 0, 0], [0, c(ax), -s(ax)], [0, s(ax), c(ax)]]
    Ry = [[c(ay), 0, s(ay)], [0, 1, 0], [-s(ay), 0, c(ay)]]
    Rz = [[c(az), -s(az), 0], [s(az), c(az), 0], [0, 0, 1]]
    np.testing.assert_allclose(euler_matrix([ax, ay, az]), np.array(Rz) @ Rx @ Ry, atol=1e-15)


@pytest.mark.parametrize("d", [2, 3])
def test_inverse_with_center_and_from_matrix(d):
    rng = np.random.default_rng(4)
    t = _random(rng, d)
    pts = rng.uniform(-50, 100, size=(20, d))
    np.testing.assert_allclose(t.inverse().apply(t.apply(pts)), pts, atol=1e-10)
    u = t.with_center(tuple(rng.uniform(-9, 9, d)))
    np.testing.assert_allclose(u.apply(pts), t.apply(pts), atol=1e-10)
    np.testing.assert_allclose(u.angles, t.angles, atol=1e-12)
    np.testing.assert_allclose(RigidTransform.from_matrix(t.matrix(), t.center).parameters, t.parameters, atol=1e-12)
    # the centre moves by the translation only
    np.testing.assert_allclose(t.apply(np.asarray(t.center)[None, :])[0], np.asarray(t.center) + t.translation)


@pytest.mark.parametrize("d", [2, 3])
def test_tfm_round_trip(tmp_path, d):
    from topomatch.stages.registration.io import write_transform

    t = _random(np.random.default_rng(d), d)
    write_transform(t, tmp_path / "t.tfm")
    back = RigidTransform.from_sitk(SimpleITK.ReadTransform(str(tmp_path / "t.tfm")), t.center)
    np.testing.assert_allclose(back.parameters, t.parameters, atol=1e-9)


def test_thesis_rotation_is_itk_rotation_of_the_opposite_angle():
    a = 12.0
    thesis_R = np.array([[math.cos(math.radians(a)), math.sin(math.radians(a))],
                         [-math.sin(math.radians(a)), math.cos(math.radians(a))]])
    np.testing.assert_allclose(thesis_R, euler_matrix([math.radians(-a)]))
    T = from_thesis(4.0, 5.0, a, (9.0, 9.0))
    assert (T.tx, T.ty) == (4.0, 5.0) and T.angle == pytest.approx(-a)
    assert T.to_thesis() == pytest.approx((4.0, 5.0, a))


def test_parameters_must_fit_the_dimension():
    with pytest.raises(ValueError, match="3 parameters"):
        RigidTransform((0.0,) * 6, (0.0, 0.0))


@pytest.mark.parametrize("d", [2, 3])
def test_tre_of_a_translation_is_its_length_everywhere(d):
    pts = np.random.default_rng(0).uniform(-40, 40, (30, d))
    shift = RigidTransform((0.0,) * (1 if d == 2 else 3) + (3.0, 4.0) + (12.0,) * (d - 2), (1.0,) * d)
    tre = target_registration_error(shift, RigidTransform.identity((0.0,) * d), pts)
    np.testing.assert_allclose(tre, 5.0 if d == 2 else 13.0)


@pytest.mark.parametrize("d", [2, 3])
def test_tre_of_a_rotation_is_its_chord(d):
    """A rotation by a about the centre moves a point at distance r from the rotation axis by 2 r sin(a / 2)."""
    c = np.array([30.0, 20.0, 10.0][:d])
    a = math.radians(10.0)
    angles = (a,) if d == 2 else (0.0, 0.0, a)  # 3D: about z
    t = RigidTransform(angles + (0.0,) * d, tuple(c))
    pts = np.random.default_rng(1).uniform(-40, 40, (25, d))
    r = np.linalg.norm((pts - c)[:, :2], axis=1)
    tre = target_registration_error(t, RigidTransform.identity(tuple(c)), pts)
    np.testing.assert_allclose(tre, 2 * math.sin(a / 2) * r, atol=1e-12)
