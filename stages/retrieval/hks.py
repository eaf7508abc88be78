"""The ``hks`` retrieval descriptor: area-weighted histograms of the heat kernel signature.

Per time ``t`` (:class:`~topomatch.stages.spectral.heat_kernel.HKSTimes`, in units of the area),
the area-weighted histogram of the log mean-normalised HKS
(:func:`~topomatch.stages.spectral.heat_kernel.heat_kernel_signature`) with ``bins`` bins on
[-3, 3], each summing to 1; the times' histograms concatenated, (n_times * bins,); compared with
the L1 distance. Isometry invariant, so it does not change when an articulated shape bends
(Sun, Ovsjanikov, Guibas, SGP 2009).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import stage
from topomatch.stages.retrieval.baselines.vectors import pairwise
from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult
from topomatch.stages.spectral.heat_kernel import HKSTimes, heat_kernel_signature
from topomatch.stages.spectral.spectrum import Spectrum


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
    return pairwise(X, Y, metric="cityblock")


@stage("hks", params=HKSParams, version=1, consumes=("spectrum",), produces=("descriptor",))
def hks_stage(spectrum: Spectrum, *, params: HKSParams) -> DescriptorResult:
    """Heat-kernel-signature histograms (Sun et al. 2009), scale-normalised."""
    return DescriptorResult(Descriptor("vector", hks_histograms(spectrum, params)))
