"""Scoring a registration against a known transform: parameter errors and target registration error.

The known transform (``truth``: a mapping with ``tx``, ``ty``, ``angle``; missing keys are 0) is
read in the same ITK convention as the estimate, about the fixed image's centre
``((W - 1) / 2, (H - 1) / 2)``.

The **target registration error** of a pixel x of the fixed grid is ``|T_est(x) - T_true(x)|``
in pixels; ``tre_mean`` is its mean over every pixel of the fixed image and ``tre_max`` its
maximum (at a corner). A registration succeeds when ``tre_mean <= threshold`` (1 px by default).
Angle errors are wrapped to (-180, 180].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, StageResult, stage
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.register import Registration
from topomatch.stages.registration.transform import RigidTransform, target_registration_error

TRUTH_KEYS = ("tx", "ty", "angle")


class EvaluateParams(Params):
    """Parameters of :func:`evaluate`."""

    threshold: float = Field(1.0, gt=0, allow_inf_nan=False, description="success: mean TRE at most this (pixels)")


def truth_transform(truth: dict[str, Any] | None, fixed: Image) -> RigidTransform:
    """The known transform as a :class:`RigidTransform` about the fixed image's centre.

    Raises
    ------
    StageError
        No truth, unknown keys or non-numeric values.
    """
    if not truth:
        raise StageError("evaluate needs a known transform: give pairs[].truth, pairs_csv.truth_columns, "
                         "or a misalign stage before it")
    unknown = sorted(set(truth) - set(TRUTH_KEYS))
    if unknown:
        raise StageError(f"truth has unknown keys {unknown}; expected {', '.join(TRUTH_KEYS)}")
    try:
        tx, ty, angle = (float(truth.get(k, 0.0)) for k in TRUTH_KEYS)
    except (TypeError, ValueError) as exc:
        raise StageError(f"truth values must be numbers, got {truth} ({exc})") from None
    H, W = fixed.shape
    return RigidTransform(tx, ty, angle, ((W - 1) / 2.0, (H - 1) / 2.0)).with_center(fixed.center)


@dataclass(frozen=True, eq=False)
class EvaluateResult(StageResult):
    """Errors of one registration against the truth.

    Attributes
    ----------
    method : str
        The registration's method label.
    d_tx, d_ty, d_angle : float
        Estimate minus truth (pixels, pixels, degrees).
    tre_mean, tre_max : float
        Target registration error over the fixed grid (pixels).
    success : bool
        ``tre_mean <= threshold``.
    flagged : bool
        The registration's own self-check failed (``not registration.ok``).
    seconds : float
        The registration's time.
    """

    method: str
    d_tx: float
    d_ty: float
    d_angle: float
    tre_mean: float
    tre_max: float
    success: bool
    flagged: bool
    seconds: float
    truth: dict[str, float]

    def summary(self) -> dict:
        return {"method": self.method, "d_tx": self.d_tx, "d_ty": self.d_ty, "d_angle": self.d_angle,
                "tre_mean": self.tre_mean, "tre_max": self.tre_max, "success": self.success,
                "flagged": self.flagged, "seconds": self.seconds}


def evaluate_registration(fixed: Image, registration: Registration, truth: dict[str, Any] | None,
                          params: EvaluateParams = EvaluateParams()) -> EvaluateResult:
    """Compare ``registration`` with ``truth`` on the fixed image's grid."""
    true_t = truth_transform(truth, fixed)
    est = registration.transform.with_center(fixed.center)
    tre = target_registration_error(est, true_t, fixed.shape)
    d_angle = (est.angle - true_t.angle + 180.0) % 360.0 - 180.0
    mean = float(tre.mean())
    return EvaluateResult(registration.method, est.tx - true_t.tx, est.ty - true_t.ty, d_angle, mean,
                          float(tre.max()), bool(mean <= params.threshold) if math.isfinite(mean) else False,
                          not registration.ok, registration.seconds,
                          {"tx": true_t.tx, "ty": true_t.ty, "angle": true_t.angle})


@stage("evaluate", params=EvaluateParams, version=1, consumes=("fixed", "registration", "truth"))
def evaluate(fixed: Image, registration: Registration, truth, *, params: EvaluateParams) -> EvaluateResult:
    """Errors in tx, ty, angle and mean/max target registration error against the known transform."""
    return evaluate_registration(fixed, registration, truth, params)
