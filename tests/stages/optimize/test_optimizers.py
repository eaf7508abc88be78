"""SPSA and Powell on functions with known maxima: convergence, determinism, bounds, history, stops."""

from __future__ import annotations

import math

import numpy as np
import pytest

from topomatch.stages.optimize.powell import PowellSettings, powell_maximize
from topomatch.stages.optimize.spsa import SPSASettings, spsa_maximize

TARGET = np.array([3.0, -2.0, 5.0])


def quadratic(theta):
    return -float(np.sum((np.asarray(theta) - TARGET) ** 2))


@pytest.mark.parametrize("normalize", [False, True])
def test_spsa_finds_the_maximum_of_a_quadratic(normalize):
    s = SPSASettings(iterations=300, step=0.5, c=0.2, normalize=normalize, newton=0.5, c_step_ratio=1.0,
                     alpha=1.0 if normalize else 0.602)
    res = spsa_maximize(quadratic, np.zeros(3), s, rng=np.random.default_rng(0))
    np.testing.assert_allclose(res.theta, TARGET, atol=0.05)
    assert res.value == pytest.approx(quadratic(res.theta))
    assert res.history["theta"].shape == (res.iterations, 3)
    assert res.evaluations >= 2 * res.iterations


def test_normalised_spsa_on_a_cone_with_parameter_scaling():
    """A cone -|(t - T) / scale|: isotropic only in the scaled units z = theta / scales that SPSA works in."""
    target, scales = np.array([3.0, -2.0, 50.0]), np.array([1.0, 1.0, 10.0])

    def cone(theta):
        return -float(np.linalg.norm((np.asarray(theta) - target) / scales))

    res = spsa_maximize(cone, np.zeros(3), SPSASettings(iterations=400, step=1.0, c=0.5, normalize=True,
                                                        c_step_ratio=1.0, alpha=1.0),
                        rng=np.random.default_rng(1), scales=scales)
    assert np.all(np.abs(res.theta - target) / scales < 0.1)


def test_spsa_same_seed_same_result_and_history():
    s = SPSASettings(iterations=50, step=0.5, normalize=True)
    a = spsa_maximize(quadratic, np.zeros(3), s, rng=np.random.default_rng(5))
    b = spsa_maximize(quadratic, np.zeros(3), s, rng=np.random.default_rng(5))
    c = spsa_maximize(quadratic, np.zeros(3), s, rng=np.random.default_rng(6))
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_array_equal(a.history["theta"], b.history["theta"])
    assert not np.array_equal(a.theta, c.theta)


def test_spsa_respects_bounds():
    res = spsa_maximize(quadratic, np.zeros(3), SPSASettings(iterations=200, step=1.0, c=0.5, normalize=True,
                                                             c_step_ratio=1.0, alpha=1.0),
                        rng=np.random.default_rng(0), lower=[-1, -1, -1], upper=[1, 1, 1])
    assert np.all(res.theta <= 1) and np.all(res.theta >= -1)
    np.testing.assert_allclose(res.theta, [1, -1, 1], atol=0.2)
    assert np.all(np.abs(res.history["theta"]) <= 1)


def test_spsa_stop_reasons_and_callback():
    seen = []
    res = spsa_maximize(quadratic, np.zeros(3), SPSASettings(iterations=100), rng=np.random.default_rng(0),
                        callback=lambda k, th, v: seen.append(k) or k >= 4)
    assert res.stop_reason == "callback" and res.iterations == 5 and seen == [0, 1, 2, 3, 4]
    res = spsa_maximize(quadratic, TARGET, SPSASettings(iterations=500, step=1e-4, normalize=True, tol=1e-3, window=5),
                        rng=np.random.default_rng(0))
    assert res.stop_reason == "converged" and res.iterations == 5
    res = spsa_maximize(lambda t: -math.inf, np.zeros(3), SPSASettings(), rng=np.random.default_rng(0))
    assert res.stop_reason == "invalid_start" and res.iterations == 0
    res = spsa_maximize(lambda t: 1.0, np.zeros(3), SPSASettings(), rng=np.random.default_rng(0))
    assert res.stop_reason == "flat_objective"


def test_spsa_steps_away_from_invalid_points():
    """f = -inf beyond x0 > 2: the iterate must stay where f is finite and still approach the constrained max."""
    def f(theta):
        return -math.inf if theta[0] > 2.0 else quadratic(theta)

    res = spsa_maximize(f, np.zeros(3), SPSASettings(iterations=300, step=0.5, c=0.3, normalize=True, c_step_ratio=1.0,
                                                     alpha=1.0), rng=np.random.default_rng(2))
    assert math.isfinite(res.value) and res.theta[0] <= 2.0
    assert res.theta[0] > 1.5


def test_blocking_never_accepts_a_worse_point():
    s = SPSASettings(iterations=60, step=2.0, c=0.5, normalize=True, blocking=True, shrink=0.5)
    res = spsa_maximize(quadratic, np.zeros(3), s, rng=np.random.default_rng(3))
    values = [quadratic(t) for t in res.history["theta"]]
    assert all(b >= a - 1e-12 for a, b in zip(values, values[1:]))
    assert res.history["blocked"].any()


def test_max_step_limits_every_step():
    s = SPSASettings(iterations=30, step=5.0, c=0.5, max_step=0.25)
    res = spsa_maximize(quadratic, np.zeros(3), s, rng=np.random.default_rng(4))
    assert res.history["step"].max() <= 0.25 + 1e-12


def test_powell_is_deterministic_and_accurate():
    a = powell_maximize(quadratic, np.zeros(3), PowellSettings(xtol=1e-4))
    b = powell_maximize(quadratic, np.zeros(3), PowellSettings(xtol=1e-4))
    np.testing.assert_allclose(a.theta, TARGET, atol=1e-3)
    np.testing.assert_array_equal(a.theta, b.theta)
    assert a.iterations == len(a.history["value"]) > 0


def test_powell_handles_invalid_points():
    def f(theta):
        return -math.inf if theta[0] > 2.0 else quadratic(theta)

    res = powell_maximize(f, np.zeros(3), PowellSettings(xtol=1e-4), lower=[-10, -10, -10], upper=[10, 10, 10])
    assert res.theta[0] <= 2.0 + 1e-9 and math.isfinite(res.value)


@pytest.mark.parametrize("answer, stops", [(None, False), (False, False), (True, True), (np.True_, True), (1, True),
                                           (0, False)])
def test_callback_answers_that_stop_or_go_on(answer, stops):
    from topomatch.stages.optimize.spsa import callback_stops

    assert callback_stops(answer) is stops


@pytest.mark.parametrize("answer", [np.array([True, False]), "stop", 0.5, [True]])
def test_a_callback_answer_that_is_not_a_bool_is_a_type_error_naming_the_contract(answer):
    from topomatch.stages.optimize.spsa import callback_stops

    with pytest.raises(TypeError, match="must return True \\(stop\\), False or None, not"):
        callback_stops(answer)
