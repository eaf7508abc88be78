"""Heat kernel signature (HKS) of every vertex, scale-normalised, and its area-weighted histograms.

Sun, Ovsjanikov, Guibas, "A concise and provably informative multi-scale signature based on heat
diffusion", SGP 2009: ``h_t(x) = sum_i exp(-lambda_i t) phi_i(x)^2`` over the eigenpairs of the
Laplace-Beltrami operator (:mod:`topomatch.stages.spectral.spectrum`). It is an isometry invariant, so it
does not change when an articulated shape bends.

Scale: times are given in units of the surface area (``t = tau * A``), so ``lambda_i t`` does not
change when the shape is scaled; each scale is then divided by its area-weighted mean over the
surface (``h_t / (1/A) sum_x m_x h_t(x)``), which removes the ``1 / A`` of ``phi^2``, and its
logarithm is taken. With the default 60 eigenpairs the smallest time 0.005 A still has
``exp(-lambda_60 t) ~ exp(-60 * 4 pi * 0.005) ~ 0.02``: the truncation is harmless there.

The shape descriptor (``hks`` stage) is the area-weighted histogram of the log signature at each
time (bins on [-3, 3]), concatenated: (times * bins,); compared with the L1 distance.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from topomatch.pipeline.params import Params
from topomatch.pipeline.registry import stage
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


class HKSParams(HKSTimes):
    """Times and histogram of the ``hks`` descriptor."""

    bins: int = Field(32, ge=2, le=1024, description="histogram bins per time on [-3, 3] (log HKS / mean)")


def hks_histograms(spectrum: Spectrum, params: HKSParams) -> np.ndarray:
    """(n_times * bins,) area-weighted histograms of the log HKS, each summing to 1."""
    S = heat_kernel_signature(spectrum, params.times())
    edges = np.linspace(-3.0, 3.0, params.bins + 1)
    out = []
    for column in S.T:
        h, _ = np.histogram(np.clip(column, -3.0, 3.0), bins=edges, weights=spectrum.mass)
        out.append(h / h.sum())
    return np.concatenate(out)


def distance_matrix(X: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
    """(n, m) L1 distances between HKS histogram rows."""
    from topomatch.stages.retrieval.baselines.vectors import pairwise

    return pairwise(X, Y, metric="cityblock")


@stage("hks", params=HKSParams, version=1, consumes=("spectrum",), produces=("descriptor",))
def hks_stage(spectrum: Spectrum, *, params: HKSParams):
    """Heat-kernel-signature histograms (Sun et al. 2009), scale-normalised."""
    from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult

    return DescriptorResult(Descriptor("vector", hks_histograms(spectrum, params)))
