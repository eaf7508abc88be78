"""The mixture distance function of thesis chapter 3 (RGPD).

For vertices p_i (m of them) and a centre c, with centred coordinates
q_i = p_i - c and A = m (V_c^T V_c)^{-1}:

- Euclidean: e_i = ||q_i||^2
- affine (Mahalanobis): a_i = q_i^T A q_i
- mixture: d_i = lambda e_i + (1 - lambda) a_i, with the data-dependent
  lambda = max_i e_i / (e_i + a_i)
- normalised: d~ = (d - min d) / (max d - min d) in [0, 1].

Choice (documented deviation, option ``euclidean_scale``): the thesis mixes a
squared length (e_i) with a dimensionless quantity (a_i), so neither lambda nor
d~ would be invariant to a uniform scale of the mesh, which the thesis claims
(Fig. 3.11). By default topomatch divides e_i by its mean over the vertices,
mean ||q_i||^2, which makes both terms dimensionless and the whole function
invariant to rotation, translation and uniform scale (the mean of a_i is 3 by
construction). ``euclidean_scale="none"`` gives the literal formula.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from topomatch.pipeline.contract import StageError
from topomatch.stages.morse.centroid import CENTROIDS
from topomatch.stages.morse.function import MorseFunction, normalized


def mixture_distance(
    V: np.ndarray,
    F: np.ndarray,
    *,
    kind: Literal["mixture", "euclidean", "affine"] = "mixture",
    centroid: Literal["vertices", "area", "enclosing_sphere"] = "vertices",
    lam: float | None = None,
    euclidean_scale: Literal["mean_squared_radius", "none"] = "mean_squared_radius",
) -> MorseFunction:
    """Normalised mixture (or pure Euclidean / affine) distance from the centre.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions.
    F : (m, 3) int64
        Triangles (used by the area centroid only).
    kind : {'mixture', 'euclidean', 'affine'}
        Which distance.
    centroid : {'vertices', 'area', 'enclosing_sphere'}
        The centre c (see :mod:`topomatch.stages.morse.centroid`).
    lam : float in (0, 1), optional
        Fixed mixture weight; None uses the data-dependent lambda.
    euclidean_scale : {'mean_squared_radius', 'none'}
        Divide e_i by mean ||q_i||^2 (scale-invariant, default) or not (thesis literal).

    Returns
    -------
    MorseFunction
        ``values`` (n,) in [0, 1], ``root`` = c, ``info`` with lambda.
    """
    V = np.asarray(V, dtype=np.float64)
    c = CENTROIDS[centroid](V, F)
    Q = V - c
    cov = Q.T @ Q
    if np.linalg.matrix_rank(cov) < 3:
        raise StageError("the vertices lie in a plane or on a line: the affine (Mahalanobis) term is undefined")
    A = len(V) * np.linalg.inv(cov)
    e = np.einsum("ij,ij->i", Q, Q)
    if euclidean_scale == "mean_squared_radius":
        e = e / e.mean()
    a = np.einsum("ij,jk,ik->i", Q, A, Q)
    if kind == "euclidean":
        d, weight = e, 1.0
    elif kind == "affine":
        d, weight = a, 0.0
    else:
        weight = float(np.max(e / np.maximum(e + a, 1e-300))) if lam is None else float(lam)
        d = weight * e + (1.0 - weight) * a
    return MorseFunction(normalized(d), kind, root=c, info={"lambda": weight, "centroid": centroid})
