"""Entropies and divergences: analytic values that no one here chose."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.stages.registration.divergence import (conditionals, jensen_renyi, jensen_renyi_histogram, jensen_tsallis,
                                            jensen_tsallis_histogram,
                                            mutual_information, renyi_entropy, shannon_entropy, similarity,
                                            tsallis_entropy, tsallis_mutual_information)


def test_shannon_of_uniform_and_one_hot():
    assert shannon_entropy(np.full(8, 1 / 8)) == pytest.approx(math.log(8))
    assert shannon_entropy(np.array([0.0, 1.0, 0.0])) == 0.0


@pytest.mark.parametrize("alpha", [0.3, 0.5, 2.0, 3.0])
def test_tsallis_and_renyi_of_uniform(alpha):
    k = 5
    p = np.full(k, 1 / k)
    assert tsallis_entropy(p, alpha) == pytest.approx((k ** (1 - alpha) - 1) / (1 - alpha))
    assert renyi_entropy(p, alpha) == pytest.approx(math.log(k))  # Renyi of a uniform is log k for every alpha


def test_tsallis_bernoulli_maximum_at_one_half():
    p = np.linspace(0, 1, 101)
    h = tsallis_entropy(np.column_stack([p, 1 - p]), 2.0, axis=1)
    assert p[np.argmax(h)] == pytest.approx(0.5)
    assert h.max() == pytest.approx(0.5)  # 1 - 2 * (1/2)^2
    assert h[0] == h[-1] == 0.0


@pytest.mark.parametrize("entropy", [tsallis_entropy, renyi_entropy])
def test_generalised_entropies_tend_to_shannon(entropy):
    p = np.array([0.5, 0.25, 0.125, 0.125, 0.0])
    h = shannon_entropy(p)
    assert entropy(p, 1.0) == pytest.approx(h, abs=1e-15)
    assert entropy(p, 1.0 + 1e-6) == pytest.approx(h, abs=1e-5)
    assert entropy(p, 1.0 - 1e-6) == pytest.approx(h, abs=1e-5)


def test_jt_zero_for_identical_distributions():
    p = np.array([0.1, 0.6, 0.3, 0.0])
    P = np.tile(p, (4, 1))
    for alpha in (0.5, 1.0, 2.0):
        assert jensen_tsallis(P, np.full(4, 0.25), alpha) == pytest.approx(0.0, abs=1e-15)
        assert jensen_renyi(P, np.array([0.1, 0.2, 0.3, 0.4]), alpha) == pytest.approx(0.0, abs=1e-15)


def test_jt_maximal_for_one_hot_conditionals():
    """One-hot rows have zero entropy, so JT = H_alpha(mixture), the largest value for that mixture."""
    rng = np.random.default_rng(0)
    w = np.array([0.2, 0.3, 0.5])
    one_hot = np.eye(3)
    jt_max = jensen_tsallis(one_hot, w, 2.0)
    assert jt_max == pytest.approx(tsallis_entropy(w, 2.0))
    for _ in range(50):  # any other rows with the same mixture give less
        P = rng.dirichlet(np.ones(3), size=3)
        P = P / P.sum(axis=1, keepdims=True)
        assert jensen_tsallis(P, w, 2.0) <= jensen_tsallis(one_hot, w, 2.0) + 1e-12


def test_jt_non_negative_random():
    rng = np.random.default_rng(1)
    for alpha in (0.3, 1.0, 1.5, 2.0):
        for _ in range(20):
            P = rng.dirichlet(np.ones(6), size=4)
            assert jensen_tsallis(P, rng.dirichlet(np.ones(4)), alpha) >= -1e-12


def test_mi_of_a_variable_with_itself_is_its_entropy():
    rng = np.random.default_rng(2)
    counts = rng.integers(1, 50, size=7).astype(float)
    h = np.diag(counts)
    assert mutual_information(h) == pytest.approx(shannon_entropy(counts / counts.sum()))


def test_jt_alpha_one_histogram_weights_equals_mi():
    rng = np.random.default_rng(3)
    h = rng.integers(0, 20, size=(6, 9)).astype(float)
    h[2] = 0  # an empty row
    assert jensen_tsallis_histogram(h, 1.0, "histogram") == pytest.approx(mutual_information(h), abs=1e-12)
    assert jensen_tsallis_histogram(h, 1.0 + 1e-7, "histogram") == pytest.approx(mutual_information(h), abs=1e-6)


def test_alpha2_identity_of_the_thesis():
    rng = np.random.default_rng(4)
    for _ in range(10):
        h = rng.integers(0, 9, size=(8, 8)).astype(float)
        h[rng.integers(0, 8)] = 0  # empty row
        h[:, rng.integers(0, 8)] = 0  # empty column
        P, w = conditionals(h, "histogram")
        general = jensen_tsallis(P, w, 2.0)
        assert jensen_tsallis_histogram(h, 2.0) == pytest.approx(general, abs=1e-13)  # the fast path
        assert jensen_tsallis_histogram(h, 2.0 + 1e-12) == pytest.approx(general, abs=1e-9)  # the general path


@pytest.mark.parametrize("weights", ["histogram", "uniform"])
@pytest.mark.parametrize("metric", ["jt", "jr"])
def test_empty_rows_are_left_out(metric, weights):
    rng = np.random.default_rng(5)
    h = rng.integers(1, 9, size=(5, 6)).astype(float)
    padded = np.vstack([np.zeros((2, 6)), h, np.zeros((1, 6))])
    a = similarity(h, metric, alpha=1.5, weights=weights)
    b = similarity(padded, metric, alpha=1.5, weights=weights)
    assert np.isfinite(b) and b == pytest.approx(a, abs=1e-13)


@pytest.mark.parametrize("metric", ["jt", "jr", "mi", "tmi"])
def test_empty_histogram_is_nan_not_an_error(metric):
    assert math.isnan(similarity(np.zeros((4, 4)), metric))


def test_uniform_weights_are_uniform_over_non_empty_rows():
    h = np.array([[4.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    P, w = conditionals(h, "uniform")
    np.testing.assert_allclose(w, [0.5, 0.5])
    np.testing.assert_allclose(P, [[1, 0], [0, 1]])
    assert jensen_tsallis_histogram(h, 2.0, "uniform") == pytest.approx(0.5)  # H_2((1/2, 1/2)) - 0


@pytest.mark.parametrize("form", ["additive", "relative"])
def test_tsallis_mi_zero_for_independent_and_tends_to_mi(form):
    px, py = np.array([0.2, 0.5, 0.3]), np.array([0.1, 0.4, 0.4, 0.1])
    assert tsallis_mutual_information(np.outer(px, py) * 1000, 2.0, form) == pytest.approx(0.0, abs=1e-12)
    rng = np.random.default_rng(6)
    h = rng.integers(0, 10, size=(4, 5)).astype(float)
    assert tsallis_mutual_information(h, 1.0 + 1e-7, form) == pytest.approx(mutual_information(h), abs=1e-5)


def test_jensen_renyi_histogram_matches_definition():
    h = np.array([[3.0, 1.0, 0.0], [0.0, 2.0, 2.0]])
    P = h / h.sum(axis=1, keepdims=True)
    w = h.sum(axis=1) / h.sum()
    expected = renyi_entropy(w @ P, 0.5) - w @ renyi_entropy(P, 0.5, axis=1)
    assert jensen_renyi_histogram(h, 0.5) == pytest.approx(expected)


def test_bad_weights_and_alpha_rejected():
    with pytest.raises(ValueError, match="sum to 1"):
        jensen_tsallis(np.eye(2), np.array([0.7, 0.7]), 2.0)
    with pytest.raises(ValueError, match="alpha must be > 0"):
        tsallis_entropy(np.array([0.5, 0.5]), 0.0)
    with pytest.raises(ValueError, match="unknown metric"):
        similarity(np.eye(2), "nmi")
