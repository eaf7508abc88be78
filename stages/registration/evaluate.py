"""Scoring a registration against a known transform, 2D and 3D: parameter errors and target registration error.

The known transform (``truth``: a mapping from the parameter names of :data:`~.transform.NAMES` to values, angles in
degrees; missing names are 0; an optional ``center``) is read in the estimate's convention, about the fixed grid's
centre unless it gives its own.

The **target registration error** of a fixed point p is ``|T_est(p) - T_true(p)|`` (physical units); ``tre_mean`` is its
mean over the fixed grid's pixels (``region: all``, the 2D default) or over its Otsu foreground (``foreground``, the 3D
default: the head, not the air around it), ``tre_max`` its maximum. A registration succeeds when ``tre_mean <=
threshold``. Angle errors are wrapped to (-180, 180]."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.registration.image import Image, foreground_mask
from topomatch.stages.registration.register import Registration
from topomatch.stages.registration.transform import NAMES, RigidTransform, n_angles, target_registration_error


class EvaluateParams(Params):
    """Parameters of :func:`evaluate`."""

    threshold: float = Field(1.0, gt=0, allow_inf_nan=False, description="success: mean TRE at most this (physical "
                                                                         "units: pixels for a PNG, mm for a volume)")
    region: Literal["all", "foreground"] | None = Field(None, description="fixed points of the TRE: every pixel, or "
                                                                          "the Otsu foreground (default: 2D all, 3D "
                                                                          "foreground)")


def truth_transform(truth: dict[str, Any] | None, fixed: Image) -> RigidTransform:
    """The known transform about the fixed grid's centre (StageError: no truth, unknown keys, non-numeric values)."""
    if not truth:
        raise StageError("evaluate needs a known transform: give pairs[].truth, pairs_csv.truth_columns, "
                         "or a misalign stage before it")
    names = NAMES[fixed.dim]
    if unknown := sorted(set(truth) - set(names) - {"center"}):
        raise StageError(f"truth has unknown keys {unknown}; expected {', '.join(names)} (and center)")
    try:
        values = [float(truth.get(n, 0.0)) for n in names]
        center = [float(c) for c in truth.get("center", fixed.center)]
    except (TypeError, ValueError) as exc:
        raise StageError(f"truth values must be numbers, got {truth} ({exc})") from None
    return RigidTransform.from_degrees(values, center).with_center(fixed.center)


def tre_points(fixed: Image, region: str | None = None, max_points: int = 50000) -> np.ndarray:
    """The fixed points (n, d) the TRE is averaged over (every ``ceil(count / max_points)``-th of the region)."""
    region = region or ("all" if fixed.dim == 2 else "foreground")
    flat = np.flatnonzero(foreground_mask(fixed).ravel()) if region == "foreground" else np.arange(fixed.data.size)
    return fixed.points(flat[:: int(math.ceil(len(flat) / max_points))])


@dataclass(frozen=True, eq=False)
class EvaluateResult(StageResult):
    """Errors of one registration against the truth: ``errors`` estimate minus truth per parameter name (angles in
    degrees, wrapped); ``d_rotation`` the angle of the rotation between them (degrees); ``d_translation`` the length
    of the translations' difference (about the fixed centre); ``success`` ``tre_mean <= threshold``; ``flagged``
    the registration's own self-check failed; ``truth`` the true parameters by name (angles in degrees)."""

    method: str
    errors: dict[str, float]
    d_rotation: float
    d_translation: float
    tre_mean: float
    tre_max: float
    success: bool
    flagged: bool
    seconds: float
    truth: dict[str, float]

    def summary(self) -> dict:
        return {"method": self.method, **{f"d_{k}": v for k, v in self.errors.items()}, "d_rotation": self.d_rotation,
                "d_translation": self.d_translation, "tre_mean": self.tre_mean, "tre_max": self.tre_max,
                "success": self.success, "flagged": self.flagged, "seconds": self.seconds}


def evaluate_registration(fixed: Image, registration: Registration, truth: dict[str, Any] | None,
                          params: EvaluateParams = EvaluateParams()) -> EvaluateResult:
    """Compare ``registration`` with ``truth`` on the fixed image's grid."""
    true_t = truth_transform(truth, fixed)
    est = registration.transform.with_center(fixed.center)
    tre = target_registration_error(est, true_t, tre_points(fixed, params.region))
    k = n_angles(fixed.dim)
    d = np.asarray(est.parameters) - np.asarray(true_t.parameters)
    d[:k] = np.degrees((d[:k] + math.pi) % (2 * math.pi) - math.pi)
    cos = (np.trace(est.rotation @ true_t.rotation.T) - (fixed.dim - 2)) / 2.0
    mean = float(tre.mean())
    return EvaluateResult(registration.method, dict(zip(est.names, map(float, d))),
                          math.degrees(math.acos(max(-1.0, min(1.0, cos)))), float(np.linalg.norm(d[k:])), mean,
                          float(tre.max()), bool(mean <= params.threshold), not registration.ok, registration.seconds,
                          true_t.degrees())


@stage("evaluate", params=EvaluateParams, version=2, consumes=("fixed", "registration", "truth"))
def evaluate(fixed: Image, registration: Registration, truth, *, params: EvaluateParams) -> EvaluateResult:
    """Errors per parameter, rotation and translation errors and mean/max target registration error against the
    known transform."""
    return evaluate_registration(fixed, registration, truth, params)
