"""The rigid 3D transform in ITK's convention (SimpleITK's ``Euler3DTransform``), physical millimetres.

A physical point ``p`` (LPS, mm) of the fixed volume maps to the moving volume by::

    T(p) = R (p - c) + c + t,      R = Rz(az) @ Rx(ax) @ Ry(ay)

with ``c`` the physical centre of the fixed volume, ``t = (tx, ty, tz)`` in mm and the Euler angles
``(ax, ay, az)`` in radians, exactly as ``sitk.Euler3DTransform(c, ax, ay, az, t)`` with its default
``ComputeZYX = False`` (ITK applies the rotation about y first, then x, then z). Registration
finds T with ``fixed(p) ~ moving(T(p))``: T is the fixed-to-moving point map that SimpleITK's and
elastix's rigid registrations return, and the one ``sitk.Resample(moving, fixed, T)`` uses.

The parameter vector is SimpleITK's order ``theta = (ax, ay, az, tx, ty, tz)``. :meth:`matrix4`
is the 4 x 4 homogeneous matrix of T (``[[R, c + t - R c], [0, 0, 0, 1]]``), independent of the
centre chosen to write it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def euler_matrix(ax: float, ay: float, az: float) -> np.ndarray:
    """``Rz(az) @ Rx(ax) @ Ry(ay)`` (radians), ITK's ``Euler3DTransform`` rotation (ComputeZYX off)."""
    cx, sx = math.cos(ax), math.sin(ax)
    cy, sy = math.cos(ay), math.sin(ay)
    cz, sz = math.cos(az), math.sin(az)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    Ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    Rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Rx @ Ry


def euler_angles(R: np.ndarray) -> tuple[float, float, float]:
    """The angles ``(ax, ay, az)`` of a rotation matrix, inverse of :func:`euler_matrix` (ITK's rule:
    ``ax = asin(R[2, 1])`` in [-pi/2, pi/2])."""
    R = np.asarray(R, dtype=np.float64)
    ax = math.asin(max(-1.0, min(1.0, R[2, 1])))
    if abs(math.cos(ax)) > 1e-9:
        ay = math.atan2(-R[2, 0], R[2, 2])
        az = math.atan2(-R[0, 1], R[1, 1])
    else:  # gimbal lock: az = 0
        ay = math.atan2(R[0, 2], R[0, 0])
        az = 0.0
    return ax, ay, az


@dataclass(frozen=True)
class RigidTransform3D:
    """``T(p) = R(ax, ay, az)(p - c) + c + t`` on physical points (mm); angles in radians.

    Attributes
    ----------
    params : tuple of 6 floats
        ``(ax, ay, az, tx, ty, tz)``, SimpleITK's ``Euler3DTransform.GetParameters()`` order.
    center : tuple of 3 floats
        The fixed centre ``c`` (mm).
    """

    params: tuple[float, float, float, float, float, float] = (0.0,) * 6
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        p = tuple(float(v) for v in self.params)
        if len(p) != 6:
            raise ValueError(f"a rigid 3D transform has 6 parameters, got {len(p)}")
        object.__setattr__(self, "params", p)
        object.__setattr__(self, "center", tuple(float(v) for v in self.center))

    @property
    def angles(self) -> tuple[float, float, float]:
        return self.params[:3]  # type: ignore[return-value]

    @property
    def angles_deg(self) -> tuple[float, float, float]:
        return tuple(math.degrees(a) for a in self.angles)  # type: ignore[return-value]

    @property
    def translation(self) -> np.ndarray:
        return np.array(self.params[3:])

    @property
    def rotation(self) -> np.ndarray:
        return euler_matrix(*self.angles)

    @property
    def offset(self) -> np.ndarray:
        """``c + t - R c``: T(p) = R p + offset."""
        c = np.asarray(self.center)
        return c + self.translation - self.rotation @ c

    def matrix4(self) -> np.ndarray:
        """The 4 x 4 homogeneous matrix of T (fixed-to-moving, physical mm)."""
        M = np.eye(4)
        M[:3, :3] = self.rotation
        M[:3, 3] = self.offset
        return M

    def apply(self, points: np.ndarray) -> np.ndarray:
        """T of physical points (n, 3) -> (n, 3)."""
        return np.asarray(points, dtype=np.float64) @ self.rotation.T + self.offset

    def with_center(self, center) -> "RigidTransform3D":
        """The same map written about another centre (same angles, other translation)."""
        c = np.asarray(center, dtype=np.float64)
        t = self.offset - c + self.rotation @ c
        return RigidTransform3D(tuple(self.angles) + tuple(t), tuple(c))

    def inverse(self) -> "RigidTransform3D":
        """T^-1 (about the same centre)."""
        R = self.rotation
        Ri = R.T
        off = -Ri @ self.offset
        c = np.asarray(self.center)
        return RigidTransform3D(tuple(euler_angles(Ri)) + tuple(off - c + Ri @ c), tuple(c))

    @classmethod
    def from_matrix(cls, M: np.ndarray, center) -> "RigidTransform3D":
        """A 4 x 4 rigid homogeneous matrix written about ``center``."""
        M = np.asarray(M, dtype=np.float64)
        c = np.asarray(center, dtype=np.float64)
        R = M[:3, :3]
        t = M[:3, 3] - c + R @ c
        return cls(tuple(euler_angles(R)) + tuple(t), tuple(c))

    def to_sitk(self):
        """``SimpleITK.Euler3DTransform`` of the same map."""
        import SimpleITK as sitk

        e = sitk.Euler3DTransform()
        e.SetCenter(self.center)
        e.SetRotation(*self.angles)
        e.SetTranslation(tuple(self.translation))
        return e

    @classmethod
    def from_sitk(cls, transform, center=None) -> "RigidTransform3D":
        """Any SimpleITK transform with a 3 x 3 matrix and translation (Euler3D, Versor, Affine, a
        composite of one), written about ``center`` (default: its own)."""
        import SimpleITK as sitk

        if transform.GetName() == "CompositeTransform":
            comp = sitk.CompositeTransform(transform)
            if comp.GetNumberOfTransforms() != 1:
                raise ValueError(f"expected one rigid transform, got a composite of {comp.GetNumberOfTransforms()}")
            transform = comp.GetNthTransform(0)
        tr = transform.Downcast() if hasattr(transform, "Downcast") else transform
        M = np.eye(4)
        M[:3, :3] = np.asarray(tr.GetMatrix()).reshape(3, 3)
        c = np.asarray(tr.GetCenter())
        M[:3, 3] = np.asarray(tr.GetTranslation()) + c - M[:3, :3] @ c
        return cls.from_matrix(M, c if center is None else center)


def target_registration_error(true: RigidTransform3D, estimate: RigidTransform3D, points: np.ndarray) -> np.ndarray:
    """``|T_true(p) - T_est(p)|`` (mm) at physical points (n, 3)."""
    return np.linalg.norm(true.apply(points) - estimate.apply(points), axis=1)
