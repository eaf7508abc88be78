"""Exact area, centroid and integral of a linear function over the part of a triangle
where the function lies below a value (closed forms; used to measure Reeb-graph nodes).

For a triangle with vertices sorted by value (f_a <= f_b <= f_c) and x between
f_a and f_b, the region {f <= x} is the triangle a, a + s1 (b - a), a + s2 (c - a)
with s1 = (x - f_a)/(f_b - f_a), s2 = (x - f_a)/(f_c - f_a); for x between f_b and
f_c it is the complement of the similar triangle at c. Areas, first moments and
integrals of f over such triangles have closed forms.
"""

from __future__ import annotations

import numpy as np


def _safe_div(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    return np.where(den != 0, num / np.where(den != 0, den, 1.0), 0.0)


def below(Pa, Pb, Pc, fa, fb, fc, area, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Area, first moment and integral of f over {f <= x} in each triangle.

    Parameters
    ----------
    Pa, Pb, Pc : (p, 3) float64
        Triangle corners sorted by value.
    fa, fb, fc : (p,) float64
        Their values (fa <= fb <= fc).
    area : (p,) float64
        Triangle areas.
    x : (p,) float64
        Thresholds (may be +-inf).

    Returns
    -------
    A : (p,) area, M : (p, 3) first moment (integral of position), I : (p,) integral of f.
    """
    # lower case: small triangle at a
    s1 = np.clip(_safe_div(x - fa, fb - fa), 0, 1)
    s2 = np.clip(_safe_div(x - fa, fc - fa), 0, 1)
    a_lo = area * s1 * s2
    m_lo = a_lo[:, None] * (Pa + ((Pb - Pa) * s1[:, None] + (Pc - Pa) * s2[:, None]) / 3.0)
    i_lo = a_lo * (fa + 2.0 * np.clip(x, fa, fb)) / 3.0
    # upper case: whole triangle minus the small triangle at c
    r1 = np.clip(_safe_div(fc - x, fc - fb), 0, 1)
    r2 = np.clip(_safe_div(fc - x, fc - fa), 0, 1)
    a_c = area * r1 * r2
    whole_m = area[:, None] * (Pa + Pb + Pc) / 3.0
    m_c = a_c[:, None] * (Pc + ((Pb - Pc) * r1[:, None] + (Pa - Pc) * r2[:, None]) / 3.0)
    whole_i = area * (fa + fb + fc) / 3.0
    i_c = a_c * (fc + 2.0 * np.clip(x, fb, fc)) / 3.0
    a_hi, m_hi, i_hi = area - a_c, whole_m - m_c, whole_i - i_c

    lower = x <= fb
    none = x <= fa
    full = x >= fc
    A = np.where(lower, a_lo, a_hi)
    M = np.where(lower[:, None], m_lo, m_hi)
    I = np.where(lower, i_lo, i_hi)
    A = np.where(none, 0.0, np.where(full, area, A))
    M = np.where(none[:, None], 0.0, np.where(full[:, None], whole_m, M))
    I = np.where(none, 0.0, np.where(full, whole_i, I))
    return A, M, I
