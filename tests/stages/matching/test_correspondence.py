"""Correspondence and dissimilarity: greedy, literal sequential and optimal; both readings of eq. 3.12."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from topomatch.stages.matching.correspondence import correspond, endpoint_costs
from topomatch.stages.matching.dissimilarity import match_features


def test_greedy_variants_differ_where_expected():
    C = np.array([[2.0, 1.0], [0.5, 3.0], [1.5, 0.9]])
    r, c = correspond(C, "greedy")            # global: (1,0)=0.5 then (2,1)=0.9
    assert sorted(zip(r.tolist(), c.tolist())) == [(1, 0), (2, 1)]
    r, c = correspond(C, "greedy_sequential")  # row 0 takes col 1 (1.0), row 1 takes col 0
    assert list(zip(r.tolist(), c.tolist())) == [(0, 1), (1, 0)]
    r, c = correspond(C, "optimal")
    rr, cc = linear_sum_assignment(C)
    assert C[r, c].sum() == C[rr, cc].sum()


def test_optimal_is_never_worse_than_greedy():
    rng = np.random.default_rng(3)
    for _ in range(50):
        C = rng.random((rng.integers(1, 8), rng.integers(1, 8)))
        g = C[correspond(C, "greedy")].sum()
        o = C[correspond(C, "optimal")].sum()
        assert o <= g + 1e-12
        assert len(correspond(C, "greedy")[0]) == min(C.shape)


def test_identical_sets_have_zero_dissimilarity():
    A = np.random.default_rng(0).random((6, 3))
    perm = A[::-1]
    assert match_features(A, perm).dissimilarity == 0.0
    assert match_features(A, perm, correspondence="optimal").dissimilarity == 0.0


def test_double_sum_and_unmatched_cost():
    A = np.array([[0.0, 0, 0], [1, 0, 0]])
    B = np.array([[0.0, 0, 0]])
    assert match_features(A, B, dissimilarity="double_sum").dissimilarity == endpoint_costs(A, B).sum() == 1.0
    assert match_features(A, B).dissimilarity == 0.0
    assert match_features(A, B, unmatched_cost=0.25).dissimilarity == 0.25
    empty = np.zeros((0, 3))
    assert match_features(empty, B, unmatched_cost=0.5).dissimilarity == 0.5
