"""Baseline shape descriptors measured side by side with the thesis methods.

Each module has a frozen params class (a :class:`topomatch.pipeline.params.Params`), a pure
``descriptor(mesh, params) -> np.ndarray``, a ``distance(a, b) -> float`` and a vectorised
``distance_matrix(X, Y=None) -> (n, m)``:

============================  =======================================  ==================  ========
module                        descriptor                               shape               distance
============================  =======================================  ==================  ========
:mod:`.d2`                    D2 shape distribution (Osada 2002)       (bins,) = (64,)     L1
:mod:`.spherical_harmonics`   rotation-invariant SH (Kazhdan 2003)     (radii, L+1)        L2
                                                                       = (32, 17)
:mod:`.shapedna`              ShapeDNA (Reuter 2006), lambda_i A / i   (k,) = (30,)        L2
============================  =======================================  ==================  ========

:data:`BASELINES` maps a short name to a :class:`Baseline` record for wiring into stages
and the index. :mod:`.sampling` holds the shared surface sampler.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from topomatch.pipeline.params import Params
from topomatch.stages.retrieval.baselines import d2, shapedna, spherical_harmonics


class Baseline(NamedTuple):
    """One baseline descriptor: its params type, functions and metric name."""

    name: str
    params: type[Params]
    descriptor: Callable[..., np.ndarray]
    distance: Callable[[np.ndarray, np.ndarray], float]
    distance_matrix: Callable[..., np.ndarray]
    metric: str


BASELINES: dict[str, Baseline] = {
    "d2": Baseline("d2", d2.D2Params, d2.descriptor, d2.distance, d2.distance_matrix, "L1"),
    "spherical_harmonics": Baseline("spherical_harmonics", spherical_harmonics.SphericalHarmonicsParams,
                                    spherical_harmonics.descriptor, spherical_harmonics.distance,
                                    spherical_harmonics.distance_matrix, "L2"),
    "shapedna": Baseline("shapedna", shapedna.ShapeDNAParams, shapedna.descriptor, shapedna.distance,
                         shapedna.distance_matrix, "L2"),
}

__all__ = ["BASELINES", "Baseline", "d2", "shapedna", "spherical_harmonics"]
