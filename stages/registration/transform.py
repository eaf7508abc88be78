"""The rigid transform about the image centre, in ITK's convention.

A point is ``x = (col, row)`` in pixels. The transform with parameters ``(tx, ty, angle)``,
angle in degrees, maps a point of the fixed image to a point of the moving image::

    T(x) = R(angle) (x - c) + c + t,    R(a) = [[cos a, -sin a], [sin a, cos a]],

with ``c = ((W - 1) / 2, (H - 1) / 2)`` the centre of the fixed image and ``t = (tx, ty)``.
Registration finds ``T`` such that ``moving(T(x)) ~ fixed(x)``: this is exactly SimpleITK's
``Euler2DTransform(center=c, angle=radians(angle), translation=t)`` used to resample the moving
image onto the fixed grid (origin 0, spacing 1), so parameters compare directly with
ITK/SimpleITK. Since the structure at ``x`` in the fixed image is at ``T(x)`` in the moving
image, the moving image shows the fixed content moved by ``T``: with the row axis pointing down
on screen, a positive angle turns it clockwise, ``tx > 0`` moves it right and ``ty > 0`` down.

The thesis writes ``Phi(x) = R x + t`` with ``R = [[cos a, sin a], [-sin a, cos a]]``, which is
ITK's ``R(-a)``: a thesis angle ``a`` about the same centre is the ITK angle ``-a`` with the same
translation (:func:`from_thesis`, :meth:`RigidTransform.to_thesis`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from topomatch.stages.registration.image import image_center


def rotation_matrix(angle_deg: float) -> np.ndarray:
    """``R(a) = [[cos a, -sin a], [sin a, cos a]]`` for ``a`` in degrees, shape (2, 2)."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class RigidTransform:
    """``T(x) = R(angle)(x - c) + c + (tx, ty)`` for points ``x = (col, row)`` in pixels.

    Attributes
    ----------
    tx, ty : float
        Translation in pixels (columns, rows).
    angle : float
        Rotation in degrees (ITK sign: ``R = [[cos, -sin], [sin, cos]]`` on (col, row)).
    center : tuple of float
        Rotation centre ``(cx, cy)`` in (col, row) pixels, normally the fixed image's centre.
    """

    tx: float
    ty: float
    angle: float
    center: tuple[float, float]

    @classmethod
    def for_image(cls, shape: tuple[int, int], tx: float = 0.0, ty: float = 0.0, angle: float = 0.0) -> "RigidTransform":
        """The transform with the given parameters about the centre of an image of ``shape`` (H, W)."""
        return cls(float(tx), float(ty), float(angle), image_center(shape))

    @classmethod
    def from_params(cls, theta, center: tuple[float, float]) -> "RigidTransform":
        """From a parameter vector ``(tx, ty, angle)``."""
        tx, ty, angle = (float(v) for v in theta)
        return cls(tx, ty, angle, (float(center[0]), float(center[1])))

    @property
    def params(self) -> np.ndarray:
        """``(tx, ty, angle)``, shape (3,)."""
        return np.array([self.tx, self.ty, self.angle])

    def matrix(self) -> np.ndarray:
        """The rotation ``R(angle)``, shape (2, 2)."""
        return rotation_matrix(self.angle)

    def homogeneous(self) -> np.ndarray:
        """The 3 x 3 matrix ``M`` with ``M @ (x, y, 1) = (T(x), 1)``."""
        R = self.matrix()
        c = np.asarray(self.center)
        M = np.eye(3)
        M[:2, :2] = R
        M[:2, 2] = c + np.array([self.tx, self.ty]) - R @ c
        return M

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Map points ``(n, 2)`` given as (col, row) to ``T(points)``, shape (n, 2)."""
        p = np.asarray(points, dtype=np.float64)
        c = np.asarray(self.center)
        return (p - c) @ self.matrix().T + c + np.array([self.tx, self.ty])

    def inverse(self) -> "RigidTransform":
        """``T^{-1}(y) = R(-a)(y - c) + c - R(-a) t``, about the same centre."""
        t = rotation_matrix(-self.angle) @ np.array([self.tx, self.ty])
        return RigidTransform(float(-t[0]), float(-t[1]), -self.angle, self.center)

    def to_thesis(self) -> tuple[float, float, float]:
        """The thesis's ``(tx, ty, a)`` with ``R = [[cos a, sin a], [-sin a, cos a]]`` about the same centre."""
        return (self.tx, self.ty, -self.angle)

    def with_center(self, center: tuple[float, float]) -> "RigidTransform":
        """The same map of the plane written about another centre (the translation changes)."""
        R = self.matrix()
        c_old, c_new = np.asarray(self.center), np.asarray(center, dtype=float)
        # R(x - c_old) + c_old + t = R(x - c_new) + c_new + t'  =>  t' = t + (R - I)(c_new - c_old)
        t = np.array([self.tx, self.ty]) + (R - np.eye(2)) @ (c_new - c_old)
        return RigidTransform(float(t[0]), float(t[1]), self.angle, (float(center[0]), float(center[1])))


def from_thesis(tx: float, ty: float, angle: float, center: tuple[float, float]) -> RigidTransform:
    """The ITK-convention transform of thesis parameters (``R_thesis(a) = R_ITK(-a)``)."""
    return RigidTransform(float(tx), float(ty), -float(angle), (float(center[0]), float(center[1])))


def grid_points(shape: tuple[int, int]) -> np.ndarray:
    """Centres of every pixel of an image of shape (H, W) as (col, row), shape (H * W, 2), row-major."""
    H, W = shape
    rows, cols = np.mgrid[0:H, 0:W]
    return np.column_stack([cols.ravel(), rows.ravel()]).astype(np.float64)


def target_registration_error(estimate: RigidTransform, truth: RigidTransform, shape: tuple[int, int]) -> np.ndarray:
    """``|| T_est(x) - T_true(x) ||`` in pixels for every pixel centre x of a grid of ``shape``, (H * W,)."""
    pts = grid_points(shape)
    return np.linalg.norm(estimate.apply(pts) - truth.apply(pts), axis=1)
