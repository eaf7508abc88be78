"""The ``gps`` retrieval descriptor: the distribution of distances in the global point signature embedding.

R. M. Rustamov, "Laplace-Beltrami eigenfunctions for deformation invariant shape representation", SGP 2007. A
vertex's global point signature is ``GPS(x) = (phi_1(x) / sqrt(lambda_1), ..., phi_k(x) / sqrt(lambda_k))`` with
the mass-orthonormal eigenfunctions of the shared spectrum (:data:`~topomatch.stages.retrieval.catalogue.SPECTRAL_CHAIN`):
the Euclidean distance between two signatures depends only on the intrinsic geometry (it does not change when an
articulated shape bends), not on the signs of the eigenfunctions, and not on the scale (``phi`` scales as
``1 / sqrt(area)`` and ``1 / sqrt(lambda)`` as ``sqrt(area)``). Rustamov compares shapes by D2-style histograms of
these distances (his G2 distributions, there per pair of shells of the embedding); here:

1. ``n_pairs`` [2^16] pairs of vertices drawn by their lumped areas (``spectrum.mass``) from
   ``numpy.random.default_rng(seed)``; their GPS distances over the ``k`` [20] leading non-constant eigenpairs;
2. the distances over their mean (so a part of a spectrum truncated at another k compares), histogrammed on
   [0, 3) in ``bins`` [48] bins, the farther ones in the last: (bins,) summing to 1, compared with L1;
3. as Rustamov's shells, the same histogram of the pairs both of whose points lie in the inner half of the
   embedding (GPS norm below its area-weighted median) and of those both in the outer half, appended: (3 bins,).

Only the spectrum's leading eigenpairs enter; near-equal eigenvalues can mix their eigenfunctions, which changes
the signature of a point but not (to first order) the distances, and a far eigenfunction weighs 1 / sqrt(lambda).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageError, stage
from topomatch.stages.retrieval.baselines.d2 import histogram
from topomatch.stages.retrieval.baselines.vectors import pairwise
from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult
from topomatch.stages.spectral.spectrum import Spectrum


class GPSParams(Params):
    """Parameters of the ``gps`` descriptor (:func:`gps_histograms`)."""

    k: int = Field(20, ge=1, le=500, description="leading non-constant eigenpairs in the embedding (at most the "
                                                 "spectrum's)")
    n_pairs: int = Field(1 << 16, ge=1000, le=1 << 24, description="vertex pairs drawn by their areas")
    bins: int = Field(48, ge=2, le=1024, description="histogram bins on [0, 3) mean distances, per histogram")
    seed: int = Field(0, ge=0, description="seed of numpy.random.default_rng for the pairs")


def embedding(spectrum: Spectrum, k: int) -> np.ndarray:
    """Global point signatures of the vertices over the ``k`` leading non-constant eigenpairs, (n, k)."""
    k = min(k, spectrum.values.shape[0] - 1)
    values = spectrum.values[1:k + 1]
    if not np.all(values > 0):
        raise StageError(f"the spectrum's leading eigenvalues must be positive for a GPS embedding, got "
                         f"{values[:3]}: several components? (run clean with components: largest)")
    return spectrum.vectors[:, 1:k + 1] / np.sqrt(values)


def gps_histograms(spectrum: Spectrum, params: GPSParams) -> np.ndarray:
    """(3 bins,) histograms of the GPS distances over their mean: all pairs, inner pairs, outer pairs."""
    G = embedding(spectrum, params.k)
    rng = np.random.default_rng(params.seed)
    p = spectrum.mass / spectrum.mass.sum()
    a, b = rng.choice(len(p), params.n_pairs, p=p), rng.choice(len(p), params.n_pairs, p=p)
    d = np.linalg.norm(G[a] - G[b], axis=1)
    x = d / d.mean() if d.mean() > 0 else d
    norm = np.linalg.norm(G, axis=1)
    order = np.argsort(norm)
    median = norm[order[np.searchsorted(np.cumsum(p[order]), 0.5)]]
    inner = norm <= median
    both_inner, both_outer = inner[a] & inner[b], ~inner[a] & ~inner[b]
    return np.concatenate([histogram(part, params.bins, 3.0) for part in (x, x[both_inner], x[both_outer])])


def distance_matrix(X: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
    """(n, m) L1 distances between GPS histogram rows."""
    return pairwise(X, Y, metric="cityblock")


@stage("gps", params=GPSParams, version=1, consumes=("spectrum",), produces=("descriptor",))
def gps_stage(spectrum: Spectrum, *, params: GPSParams) -> DescriptorResult:
    """Histograms of global point signature distances (Rustamov 2007), scale-invariant."""
    return DescriptorResult(Descriptor("vector", gps_histograms(spectrum, params)))
