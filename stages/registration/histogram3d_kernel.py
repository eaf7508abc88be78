"""One compiled pass for the 3D joint histogram: transform, trilinear interpolation and Parzen binning per sample.

:meth:`~topomatch.stages.registration.histogram3d.VolumeHistogram.__call__` in numpy makes a dozen temporary
arrays of the sample count (positions, clipped positions, corner indices, eight gathers, bin weights) and two
``np.bincount`` passes; at 40,000 samples that is ~4 ms per evaluation, most of it memory traffic, and a 3D
registration evaluates the measure ~2,000 times. This kernel does the same arithmetic in one loop over the
samples with no temporaries (numba, compiled on first use and cached on disk). It keeps the numpy path's
operation order (trilinear lerps, clipping, the two bin accumulators summed at the end), so the histograms
agree with it to round-off (the positions differ in the last bit: BLAS's 3 x 3 product against a plain sum);
``tests/stages/registration/test_register3d.py`` checks that. Without numba the numpy path is used.

Hand-written because no library computes a Parzen-windowed joint histogram of a rigidly resampled volume at
sample points (ITK's Mattes metric does, inside ITK's optimiser loop only).
"""

from __future__ import annotations

import numpy as np

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency; the numpy path stays correct without it
    numba = None


def _joint_histogram(A, b, P, mflat, mi, mj, mk, fbk, bmax, n_cells):  # pragma: no cover - compiled
    """Histogram accumulators and the inside count for samples ``P`` (3, n) mapped by ``A`` (3, 3) and ``b`` (3,)
    to continuous indices of the moving volume ``mflat`` (mk * mj * mi, in bin units)."""
    h0 = np.zeros(n_cells + 1)
    h1 = np.zeros(n_cells + 1)
    hi_i, hi_j, hi_k = mi - 1.0, mj - 1.0, mk - 1.0
    i0max, j0max, k0max = max(mi - 2, 0), max(mj - 2, 0), max(mk - 2, 0)
    di = 1 if mi > 1 else 0
    dj = mi if mj > 1 else 0
    dk = mi * mj if mk > 1 else 0
    bmax0 = max(bmax - 1, 0)
    n_inside = 0
    for s in range(P.shape[1]):
        x, y, z = P[0, s], P[1, s], P[2, s]
        u = A[0, 0] * x + A[0, 1] * y + A[0, 2] * z + b[0]
        v = A[1, 0] * x + A[1, 1] * y + A[1, 2] * z + b[1]
        w = A[2, 0] * x + A[2, 1] * y + A[2, 2] * z + b[2]
        if not (0.0 <= u <= hi_i and 0.0 <= v <= hi_j and 0.0 <= w <= hi_k):
            continue
        n_inside += 1
        i0, j0, k0 = min(int(u), i0max), min(int(v), j0max), min(int(w), k0max)
        fx, fy, fz = u - i0, v - j0, w - k0
        base = k0 * (mi * mj) + j0 * mi + i0
        v000, v100 = mflat[base], mflat[base + di]
        v010, v110 = mflat[base + dj], mflat[base + dj + di]
        v001, v101 = mflat[base + dk], mflat[base + dk + di]
        v011, v111 = mflat[base + dk + dj], mflat[base + dk + dj + di]
        a = v000 + fx * (v100 - v000)
        bb = v010 + fx * (v110 - v010)
        c = v001 + fx * (v101 - v001)
        d = v011 + fx * (v111 - v011)
        a += fy * (bb - a)
        c += fy * (d - c)
        a += fz * (c - a)
        val = min(max(a, 0.0), float(bmax))
        m0 = min(int(val), bmax0)
        wt = val - m0
        cell = m0 + fbk[s]
        h0[cell] += 1.0 - wt
        h1[cell + 1] += wt
    return h0, h1, n_inside


joint_histogram = None if numba is None else numba.njit(cache=True, nogil=True)(_joint_histogram)
"""The compiled kernel, or None without numba: ``joint_histogram(A, b, P, mflat, mi, mj, mk, fbk, bmax, n_cells)
-> (h0, h1, n_inside)``; the histogram is ``h0[:n_cells] + h1[:n_cells]``. (Running chunks of samples in two
threads with numba's ``prange`` made a whole KmeansTest registration no faster here: measured, not kept.)"""
