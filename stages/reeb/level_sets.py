"""Level sets of a vertex function: level values, vertex bands and iso-curves.

Conventions (used by the Reeb graph too): for N levels the level values are
l_k = min f + k (max f - min f) / N, k = 0..N (thesis: d(k) = k d_max / R for
the normalised distance). Band k is the half-open interval [l_k, l_{k+1})
(the last band is closed). A value exactly on a level therefore counts as
lying just above it, which is a consistent symbolic perturbation: no special
cases for vertices on a level.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, StageResult, stage
from topomatch.stages.mesh.geometry import min_max3


def level_values(f: np.ndarray, n_levels: int) -> np.ndarray:
    """The N + 1 level values l_0 = min f, ..., l_N = max f, (N+1,) float64."""
    f = np.asarray(f, dtype=np.float64)
    lo, hi = float(f.min()), float(f.max())
    if hi <= lo:
        hi = lo + 1.0
    return lo + (hi - lo) * np.arange(n_levels + 1) / n_levels


def band_index(values: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Band k of each value, with band k = [l_k, l_{k+1}), clipped to 0..N-1; int64 array."""
    n_bands = len(levels) - 1
    k = np.searchsorted(levels, values, side="right") - 1
    return np.clip(k, 0, n_bands - 1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class Isolines:
    """Iso-curves as segments.

    Attributes
    ----------
    segments : (s, 2, 3) float64
        Segment end points.
    level : (s,) int64
        Index k of the level value l_k of each segment (1..N-1 for interior levels).
    face : (s,) int64
        Triangle that contains each segment.
    """

    segments: np.ndarray
    level: np.ndarray
    face: np.ndarray

    def length(self) -> np.ndarray:
        """Total length per level index, as a dict-like array (N+1,) (zero where absent)."""
        seg_len = np.linalg.norm(self.segments[:, 1] - self.segments[:, 0], axis=1)
        return np.bincount(self.level, weights=seg_len, minlength=int(self.level.max(initial=0)) + 1)


def isolines(V: np.ndarray, F: np.ndarray, f: np.ndarray, levels: np.ndarray,
             which: np.ndarray | None = None, vertex_band: np.ndarray | None = None) -> Isolines:
    """Iso-curves of the piecewise-linear function ``f`` at the interior level values.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64
    f : (n,) float64
    levels : (N+1,) float64
        From :func:`level_values`; curves are computed at l_1..l_{N-1} (or at ``which``).
    which : (q,) int, optional
        Level indices to use instead of 1..N-1.
    vertex_band : (n,) int, optional
        ``band_index(f, levels)``, if already computed.

    A triangle contains a segment at l_k when its vertex bands satisfy
    min band < k <= max band; the end points lie on the two edges whose end
    values straddle l_k (value >= l_k counts as above). Only the triangles spanning two bands or
    more (a few percent) are sorted and interpolated.
    """
    V = np.asarray(V, dtype=np.float64)
    n_bands = len(levels) - 1
    ks = np.arange(1, n_bands) if which is None else np.asarray(which, dtype=np.int64)
    vb = band_index(f, levels) if vertex_band is None else vertex_band
    tb = vb[F]
    lo, hi = min_max3(tb[:, 0], tb[:, 1], tb[:, 2])  # bands of the lowest and highest vertex (band_index is monotone)
    cross = np.flatnonzero(hi > lo)
    Fc = F[cross]
    fv = f[Fc]
    order = np.argsort(fv, axis=1, kind="stable")
    Fs = np.take_along_axis(Fc, order, axis=1)         # vertices sorted by value: a, b, c
    fs = np.take_along_axis(fv, order, axis=1)
    local, lvl = _crossings(lo[cross], hi[cross], ks)
    faces = cross[local]
    Fs, fs = Fs[local], fs[local]
    x = levels[lvl]
    a, b, c = Fs[:, 0], Fs[:, 1], Fs[:, 2]
    fa, fb, fc = fs[:, 0], fs[:, 1], fs[:, 2]
    p_ac = _lerp(V[a], V[c], fa, fc, x)
    low_side = vb[b] >= lvl                            # the level lies between a and b
    p_ab = _lerp(V[a], V[b], fa, fb, x)
    p_bc = _lerp(V[b], V[c], fb, fc, x)
    other = np.where(low_side[:, None], p_ab, p_bc)
    return Isolines(np.stack([p_ac, other], axis=1), lvl, faces)


def _crossings(band_lo: np.ndarray, band_hi: np.ndarray, ks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(face, level) pairs with band_lo < level <= band_hi, for the levels in ``ks``."""
    count = band_hi - band_lo
    faces = np.repeat(np.arange(len(band_lo)), count)
    start = np.repeat(np.cumsum(count) - count, count)
    lvl = np.repeat(band_lo, count) + 1 + (np.arange(count.sum()) - start)
    keep = np.isin(lvl, ks)
    return faces[keep], lvl[keep]


def _lerp(P: np.ndarray, Q: np.ndarray, fp: np.ndarray, fq: np.ndarray, x: np.ndarray) -> np.ndarray:
    den = fq - fp
    t = np.where(den != 0, (x - fp) / np.where(den != 0, den, 1.0), 0.0)
    return P + np.clip(t, 0.0, 1.0)[:, None] * (Q - P)


# --------------------------------------------------------------------------- stage


@dataclass(frozen=True, eq=False)
class LevelSets:
    """Level values (N+1,), the band of every vertex (n,) and the iso-curves at l_1..l_{N-1}."""

    values: np.ndarray
    vertex_band: np.ndarray
    curves: Isolines

    @property
    def n_levels(self) -> int:
        return len(self.values) - 1


def compute_level_sets(V: np.ndarray, F: np.ndarray, f: np.ndarray, n_levels: int) -> LevelSets:
    """Level values, vertex bands and iso-curves of the vertex function ``f`` (n,)."""
    values = level_values(f, n_levels)
    vertex_band = band_index(f, values)
    return LevelSets(values, vertex_band, isolines(V, F, f, values, vertex_band=vertex_band))


class LevelSetParams(Params):
    """Parameters of the ``level_sets`` stage."""

    levels: int = Field(22, ge=2, le=10000, description="number N of bands (thesis: R = 22)")


@dataclass(frozen=True, eq=False)
class LevelSetResult(StageResult):
    level_sets: LevelSets

    def summary(self) -> dict:
        return {"levels": self.level_sets.n_levels, "segments": len(self.level_sets.curves.level)}


@stage("level_sets", params=LevelSetParams, version=1, consumes=("mesh", "function"), produces=("level_sets",))
def level_sets_stage(mesh, function, *, params: LevelSetParams) -> LevelSetResult:
    """N level values of the Morse function, vertex bands and iso-curves."""
    return LevelSetResult(compute_level_sets(mesh.V, mesh.F, function.values, params.levels))
