"""The rigid transform of 2D and 3D registration on physical points, ``T(p) = R (p - c) + c + t`` (``c`` the fixed
grid's centre, ``fixed(p) ~ moving(T(p))``), in ITK's convention: SimpleITK's ``Euler2DTransform`` (``R(a) = [[cos a,
-sin a], [sin a, cos a]]``) and ``Euler3DTransform`` (``R = Rz(az) Rx(ax) Ry(ay)``, ``ComputeZYX`` off), parameters as
:class:`RigidTransform` says. The thesis's R is ITK's ``R(-a)`` (:func:`from_thesis`). See docs/registration.md,
"Conventions"."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

NAMES = {2: ("angle", "tx", "ty"), 3: ("angle_x", "angle_y", "angle_z", "tx", "ty", "tz")}
"""Parameter names per dimension, SimpleITK's order."""


def n_angles(dim: int) -> int:
    """Euler angles of a rigid transform in ``dim`` dimensions (1 or 3)."""
    return len(NAMES[dim]) - dim


def euler_matrix(angles) -> np.ndarray:
    """The rotation of Euler angles (radians): one angle -> ``R(a)`` (2, 2); three -> ``Rz Rx Ry`` (3, 3)."""
    angles = [float(a) for a in np.ravel(angles)]
    if len(angles) == 1:
        c, s = math.cos(angles[0]), math.sin(angles[0])
        return np.array([[c, -s], [s, c]])
    (cx, sx), (cy, sy), (cz, sz) = ((math.cos(a), math.sin(a)) for a in angles)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
    Ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    Rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Rx @ Ry


def euler_angles(R: np.ndarray) -> tuple[float, ...]:
    """The Euler angles of a rotation matrix, inverse of :func:`euler_matrix` (3D: ITK's rule,
    ``ax = asin(R[2, 1])`` in [-pi/2, pi/2])."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape == (2, 2):
        return (math.atan2(R[1, 0], R[0, 0]),)
    ax = math.asin(max(-1.0, min(1.0, R[2, 1])))
    if abs(math.cos(ax)) > 1e-9:
        return ax, math.atan2(-R[2, 0], R[2, 2]), math.atan2(-R[0, 1], R[1, 1])
    return ax, math.atan2(R[0, 2], R[0, 0]), 0.0  # gimbal lock: az = 0


@dataclass(frozen=True)
class RigidTransform:
    """``T(p) = R(angles)(p - c) + c + t`` on physical points about the centre ``c`` (2 or 3 floats); ``parameters``:
    SimpleITK's ``GetParameters()``, 2D ``(angle, tx, ty)``, 3D ``(ax, ay, az, tx, ty, tz)``, radians and physical
    units."""

    parameters: tuple[float, ...]
    center: tuple[float, ...]

    def __post_init__(self) -> None:
        p, c = tuple(float(v) for v in self.parameters), tuple(float(v) for v in self.center)
        if len(c) not in NAMES or len(p) != len(NAMES[len(c)]):
            raise ValueError(f"a rigid transform about a {len(c)}D centre has "
                             f"{len(NAMES.get(len(c), ()))} parameters, got {len(p)}")
        object.__setattr__(self, "parameters", p)
        object.__setattr__(self, "center", c)

    @classmethod
    def identity(cls, center) -> "RigidTransform":
        return cls((0.0,) * len(NAMES[len(center)]), tuple(center))

    @classmethod
    def from_degrees(cls, theta, center) -> "RigidTransform":
        """A transform from parameters in SimpleITK's order with the angles in degrees (a config's ``theta``)."""
        k = n_angles(len(center))
        return cls(tuple(math.radians(a) for a in theta[:k]) + tuple(theta[k:]), tuple(center))

    @classmethod
    def euler2d(cls, tx: float, ty: float, angle_deg: float, center) -> "RigidTransform":
        """A 2D transform from ``(tx, ty, angle)`` with the angle in degrees (the 2D tables' convention)."""
        return cls((math.radians(angle_deg), tx, ty), tuple(center))

    @property
    def dim(self) -> int:
        return len(self.center)

    @property
    def names(self) -> tuple[str, ...]:
        return NAMES[self.dim]

    @property
    def angles(self) -> tuple[float, ...]:
        """The Euler angles (radians)."""
        return self.parameters[: n_angles(self.dim)]

    @property
    def angles_deg(self) -> tuple[float, ...]:
        return tuple(math.degrees(a) for a in self.angles)

    @property
    def translation(self) -> np.ndarray:
        return np.array(self.parameters[n_angles(self.dim):])

    def degrees(self) -> dict[str, float]:
        """The parameters by name, angles in degrees (a config's ``truth``, a table's columns)."""
        return dict(zip(self.names, (*self.angles_deg, *map(float, self.translation))))

    # the 2D tables' names: translation in physical units (pixels for a PNG), angle in degrees
    tx = property(lambda self: float(self.translation[0]))
    ty = property(lambda self: float(self.translation[1]))
    angle = property(lambda self: self.angles_deg[0] if self.dim == 2 else math.nan)

    @property
    def rotation(self) -> np.ndarray:
        return euler_matrix(self.angles)

    @property
    def offset(self) -> np.ndarray:
        """``c + t - R c``: ``T(p) = R p + offset``."""
        c = np.asarray(self.center)
        return c + self.translation - self.rotation @ c

    def matrix(self) -> np.ndarray:
        """The homogeneous (d + 1) x (d + 1) matrix of T (fixed-to-moving)."""
        M = np.eye(self.dim + 1)
        M[:-1, :-1] = self.rotation
        M[:-1, -1] = self.offset
        return M

    def apply(self, points: np.ndarray) -> np.ndarray:
        """T of points (n, d) -> (n, d)."""
        return np.asarray(points, dtype=np.float64) @ self.rotation.T + self.offset

    @classmethod
    def from_matrix(cls, M: np.ndarray, center) -> "RigidTransform":
        """A rigid homogeneous matrix written about ``center``."""
        M = np.asarray(M, dtype=np.float64)
        c = np.asarray(center, dtype=np.float64)
        R = M[:-1, :-1]
        return cls(euler_angles(R) + tuple(M[:-1, -1] - c + R @ c), tuple(c))

    def with_center(self, center) -> "RigidTransform":
        """The same map written about another centre (same angles, another translation)."""
        return RigidTransform.from_matrix(self.matrix(), center)

    def scaled(self, factor: float) -> "RigidTransform":
        """The same map on physical coordinates times ``factor`` (translation and centre times ``factor``)."""
        k = n_angles(self.dim)
        return RigidTransform(self.parameters[:k] + tuple(factor * self.translation), factor * np.asarray(self.center))

    def inverse(self) -> "RigidTransform":
        """T^-1, about the same centre."""
        return RigidTransform.from_matrix(np.linalg.inv(self.matrix()), self.center)

    def to_thesis(self) -> tuple[float, float, float]:
        """2D: the thesis's ``(tx, ty, a)`` (degrees) with ``R = [[cos a, sin a], [-sin a, cos a]]``, same centre."""
        return (self.tx, self.ty, -self.angle)

    def to_sitk(self):
        """The SimpleITK ``Euler2DTransform`` / ``Euler3DTransform`` of the same map."""
        import SimpleITK as sitk

        t = sitk.Euler2DTransform() if self.dim == 2 else sitk.Euler3DTransform()
        t.SetCenter(self.center)
        t.SetParameters(self.parameters)
        return t

    @classmethod
    def from_sitk(cls, transform, center=None) -> "RigidTransform":
        """Any SimpleITK transform with a matrix and translation (Euler, Versor, Affine, a composite of one),
        written about ``center`` (default: its own)."""
        import SimpleITK as sitk

        if transform.GetName() == "CompositeTransform":
            if (comp := sitk.CompositeTransform(transform)).GetNumberOfTransforms() != 1:
                raise ValueError(f"expected one rigid transform, got a composite of {comp.GetNumberOfTransforms()}")
            transform = comp.GetNthTransform(0)
        tr = transform.Downcast() if hasattr(transform, "Downcast") else transform
        d = tr.GetDimension()
        c = np.asarray(tr.GetCenter())
        M = np.eye(d + 1)
        M[:d, :d] = np.asarray(tr.GetMatrix()).reshape(d, d)
        M[:d, d] = np.asarray(tr.GetTranslation()) + c - M[:d, :d] @ c
        return cls.from_matrix(M, c if center is None else center)


def from_thesis(tx: float, ty: float, angle: float, center) -> RigidTransform:
    """The ITK-convention 2D transform of thesis parameters (``R_thesis(a) = R_ITK(-a)``, degrees)."""
    return RigidTransform.euler2d(tx, ty, -angle, center)


def target_registration_error(estimate: RigidTransform, truth: RigidTransform, points: np.ndarray) -> np.ndarray:
    """``|T_est(p) - T_true(p)|`` (physical units) at points (n, d), shape (n,)."""
    return np.linalg.norm(estimate.apply(points) - truth.apply(points), axis=1)
