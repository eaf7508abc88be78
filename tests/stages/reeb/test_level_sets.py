"""Level sets: level values, bands, and iso-curves equal to libigl's ``igl.isolines``."""

from __future__ import annotations

import igl
import numpy as np
import pytest

from topomatch.stages.morse.mixture import mixture_distance
from topomatch.stages.reeb.level_sets import band_index, isolines, level_values


def test_levels_and_bands():
    f = np.array([0.0, 0.25, 0.5, 0.999, 1.0])
    levels = level_values(f, 4)
    np.testing.assert_allclose(levels, [0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_array_equal(band_index(f, levels), [0, 1, 2, 3, 3])  # [l_k, l_k+1), last band closed


@pytest.mark.parametrize("name,n", [("odedstein_spot_low_resolution.obj.gz", 22), ("torus.off", 7),
                                    ("eight_genus2.off", 40)])
def test_isolines_match_libigl(bundled_mesh, name, n):
    m = bundled_mesh(name)
    f = mixture_distance(m.V, m.F).values
    levels = level_values(f, n)
    ours = isolines(m.V, m.F, f, levels)
    iV, iE, I = igl.isolines(m.V, m.F, f, levels[1:-1])
    ref_seg = iV[iE]
    ref_level = I + 1
    ours_len = np.linalg.norm(ours.segments[:, 1] - ours.segments[:, 0], axis=1)
    ref_len = np.linalg.norm(ref_seg[:, 1] - ref_seg[:, 0], axis=1)
    for k in range(1, n):
        assert ours_len[ours.level == k].sum() == pytest.approx(ref_len[ref_level == k].sum(), rel=1e-9)
    # the same segments: compare sorted midpoints of non-degenerate segments
    mid_ours = np.sort(np.round(ours.segments.mean(axis=1)[ours_len > 1e-12], 9), axis=0)
    mid_ref = np.sort(np.round(ref_seg.mean(axis=1)[ref_len > 1e-12], 9), axis=0)
    assert mid_ours.shape == mid_ref.shape
    np.testing.assert_allclose(mid_ours, mid_ref, atol=1e-8)


def test_isolines_of_a_linear_function_on_a_square():
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    f = V[:, 0].copy()
    levels = level_values(f, 4)
    curves = isolines(V, F, f, levels)
    lengths = np.bincount(curves.level, weights=np.linalg.norm(curves.segments[:, 1] - curves.segments[:, 0], axis=1))
    np.testing.assert_allclose(lengths[1:4], [1.0, 1.0, 1.0])
    np.testing.assert_allclose(curves.segments[curves.level == 2][:, :, 0], 0.5)
