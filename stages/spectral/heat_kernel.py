"""Heat kernel signature (HKS) of every vertex, scale-normalised, and its area-weighted histograms.

Sun, Ovsjanikov, Guibas, "A concise and provably informative multi-scale signature based on heat
diffusion", SGP 2009: ``h_t(x) = sum_i exp(-lambda_i t) phi_i(x)^2`` over the eigenpairs of the
Laplace-Beltrami operator (:mod:`topomatch.stages.spectral.spectrum`). It is an isometry invariant, so it
does not change when an articulated shape bends.

Scale: times are given in units of the surface area (``t = tau * A``), so ``lambda_i t`` does not
change when the shape is scaled; each scale is then divided by its area-weighted mean over the
surface (``h_t / (1/A) sum_x m_x h_t(x)``), which removes the ``1 / A`` of ``phi^2``, and its
logarithm is taken. With the spectrum stage's default 60 eigenpairs the smallest time 0.005 A still has
``exp(-lambda_60 t) ~ exp(-60 * 4 pi * 0.005) ~ 0.02``: the truncation is harmless there; the retrieval
methods' 40 leave ``~ 0.08`` (chosen on tune collections for the same retrieval, docs/retrieval.md).

The shape descriptor built from it (histograms, the ``hks`` stage) is in
:mod:`topomatch.stages.retrieval.hks`; the endpoint signatures in
:mod:`topomatch.stages.retrieval.descriptor`.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params
from topomatch.stages.spectral.spectrum import Spectrum


def heat_kernel_signature(spectrum: Spectrum, times: np.ndarray) -> np.ndarray:
    """(n, len(times)) log of the mean-normalised HKS at ``times`` (in units of the area)."""
    t = np.asarray(times, dtype=np.float64) * spectrum.area
    H = (spectrum.vectors ** 2) @ np.exp(-np.outer(spectrum.values, t))
    mean = spectrum.mass @ H / spectrum.mass.sum()
    return np.log(np.maximum(H / mean, 1e-300))


class HKSTimes(Params):
    """Log-spaced HKS times, in units of the surface area (shared by the HKS descriptors)."""

    t_min: float = Field(0.005, gt=0, description="smallest time, in units of the surface area")
    t_max: float = Field(0.5, gt=0, description="largest time, in units of the surface area")
    n_times: int = Field(8, ge=1, le=64, description="log-spaced times between t_min and t_max")

    def times(self) -> np.ndarray:
        return np.geomspace(self.t_min, self.t_max, self.n_times)
