"""The D2 shape distribution (Osada, Funkhouser, Chazelle, Dobkin 2002).

R. Osada, T. Funkhouser, B. Chazelle, D. Dobkin, "Shape distributions", ACM Transactions on
Graphics 21(4), 2002. D2 is the distribution of the Euclidean distance between two random
points on the surface.

Definition used here
--------------------
1. Draw ``2 n_pairs`` points uniformly on the surface (area-weighted triangle choice,
   uniform barycentric point, :func:`~topomatch.stages.retrieval.baselines.sampling.sample_surface`)
   from ``numpy.random.default_rng(seed)``; pair point ``i`` with point ``n_pairs + i``.
2. Normalise for scale by the **mean** of the sampled distances (Osada et al.'s "normalisation
   by mean", sec. 5.2): ``x = d / mean(d)``. Translation and rotation invariance are built in.
3. Histogram ``x`` on ``[0, max_distance)`` with ``bins`` equal bins (default 64 bins on
   ``[0, 3)``; a point pair farther than ``max_distance`` mean distances goes into the last
   bin, so the histogram is a probability vector summing to 1). Three mean distances cover
   a uniform rod (whose distances reach exactly 3 mean distances) and every compact shape; a
   sphere uses ``[0, 1.5]``.
4. Distance between two descriptors: **L1** of the histograms, ``sum |a - b|`` in ``[0, 2]``
   (Osada et al.'s "PDF L_N" norm with N = 1, one of the norms they compare).

Randomness: the descriptor is a random variable. With the defaults (2**18 pairs, 64 bins) the
expected L1 distance between two independent draws on the same shape is about 0.01 (the sum
of the per-bin standard deviations ``sqrt(p_k / n_pairs)``), while different shapes are
typically 0.1-1 apart. The same seed on a rotated, translated or uniformly scaled copy gives
the same point pairs (up to round-off), hence the same histogram up to a few pairs that cross
a bin edge.

Analytic check: on a sphere of radius R the chord length has density ``d / (2 R^2)`` on
``[0, 2 R]`` and mean ``4 R / 3``, so ``x`` has density ``8 x / 9`` on ``[0, 1.5]`` (tested).
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, stage
from topomatch.stages.mesh.mesh import Mesh
from topomatch.stages.retrieval.baselines.sampling import checked_areas, sample_surface
from topomatch.stages.retrieval.baselines.vectors import pairwise
from topomatch.stages.retrieval.descriptor import Descriptor, DescriptorResult


class D2Params(Params):
    """Parameters of the D2 shape distribution (:func:`descriptor`)."""

    n_pairs: int = Field(1 << 18, ge=1000, le=1 << 26,
                         description="number of random point pairs (Osada et al. use 1024^2; 2^18 gives a "
                                     "sampling noise of about 0.01 in L1)")
    bins: int = Field(64, ge=2, le=4096, description="number of histogram bins on [0, max_distance)")
    max_distance: float = Field(3.0, gt=0, le=100, allow_inf_nan=False,
                                description="upper end of the histogram, in mean distances; larger "
                                            "distances are counted in the last bin")
    seed: int = Field(0, ge=0, description="seed of numpy.random.default_rng for the point sampling")


def distances(mesh: Mesh, params: D2Params) -> np.ndarray:
    """The ``n_pairs`` sampled distances divided by their mean, (n_pairs,) float64.

    Raises
    ------
    InputError
        Empty mesh, bad indices, non-finite coordinates or zero area (names the mesh).
    """
    areas = checked_areas(mesh)
    rng = np.random.default_rng(params.seed)
    P = sample_surface(mesh.V, mesh.F, 2 * params.n_pairs, rng, areas, shuffle=True)
    d = np.linalg.norm(P[:params.n_pairs] - P[params.n_pairs:], axis=1)
    mean = d.mean()
    if not mean > 0:
        return np.zeros_like(d)
    return d / mean


def descriptor(mesh: Mesh, params: D2Params | None = None) -> np.ndarray:
    """D2 histogram of ``mesh``: (bins,) float64, non-negative, summing to 1.

    Parameters
    ----------
    mesh : Mesh
        ``V`` (n, 3) float64, ``F`` (m, 3) int64; any triangle mesh with positive area (not
        necessarily closed or connected).
    params : D2Params, optional
        Defaults: 2^18 pairs, 64 bins on [0, 3) mean distances, seed 0.

    Returns
    -------
    (bins,) float64
        Fraction of the pairs whose normalised distance falls in each bin (the last bin also
        holds the pairs beyond ``max_distance``).
    """
    params = D2Params() if params is None else params
    return histogram(distances(mesh, params), params.bins, params.max_distance)


def histogram(x: np.ndarray, bins: int, max_distance: float) -> np.ndarray:
    """Fractions of ``x`` (normalised distances, >= 0) in ``bins`` equal bins on ``[0, max_distance)``, the larger
    ones in the last: (bins,) summing to 1 (zeros for an empty ``x``)."""
    if x.size == 0:
        return np.zeros(bins)
    k = np.minimum((x * (bins / max_distance)).astype(np.int64), bins - 1)
    return np.bincount(k, minlength=bins) / float(x.size)


def density(x: np.ndarray, params: D2Params | None = None) -> np.ndarray:
    """Convert a histogram from :func:`descriptor` to a density on the normalised distance axis.

    Returns ``hist / bin_width`` (bins,), comparable with an analytic density of ``d / mean(d)``.
    """
    params = D2Params() if params is None else params
    return np.asarray(x, dtype=np.float64) * (params.bins / params.max_distance)


def distance(a: np.ndarray, b: np.ndarray) -> float:
    """L1 distance ``sum |a - b|`` of two D2 histograms (in [0, 2] for probability vectors)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"D2 descriptors must be 1-D of equal length, got {a.shape} and {b.shape}")
    return float(np.abs(a - b).sum())


def distance_matrix(X: np.ndarray, Y: np.ndarray | None = None) -> np.ndarray:
    """All pairwise L1 distances: ``X`` (n, bins), ``Y`` (m, bins) (default ``X``) -> (n, m) float64."""
    return pairwise(X, Y, metric="cityblock")


@stage("d2", params=D2Params, version=1, consumes=("mesh",), produces=("descriptor",))
def d2_stage(mesh: Mesh, *, params: D2Params) -> DescriptorResult:
    """D2 shape distribution (Osada et al. 2002): histogram of random surface-point distances."""
    return DescriptorResult(Descriptor("vector", descriptor(mesh, params)))
