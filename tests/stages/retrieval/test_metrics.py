"""PSB retrieval metrics: hand-computed examples, tie-breaking, averaging, invariants, chance levels."""

from __future__ import annotations

import numpy as np
import pytest

import topomatch.stages.retrieval.metrics as metrics_module
from topomatch.stages.retrieval.metrics import (METRIC_NAMES, chance_levels, precision_recall, ranked_lists,
                                      retrieval_metrics)

# log2-discounts of ranks 3, 4, 5, 6 (rank 1 and 2 weigh 1)
W3, W4, W5, W6 = 1 / np.log2(3), 1 / np.log2(4), 1 / np.log2(5), 1 / np.log2(6)


def six_items() -> tuple[np.ndarray, np.ndarray]:
    """Two classes of three (A = 0, 1, 2; B = 3, 4, 5), a symmetric D with no ties.

    Ranked lists (query removed), and the relevance G of each rank:
      q0: 1 3 2 4 5  -> 1 0 1 0 0        q3: 4 0 2 5 1  -> 1 0 0 1 0
      q1: 0 4 2 3 5  -> 1 0 1 0 0        q4: 1 3 2 5 0  -> 0 1 0 1 0
      q2: 5 3 1 4 0  -> 0 0 1 0 1        q5: 2 3 4 1 0  -> 0 1 1 0 0
    """
    upper = {(0, 1): .1, (0, 2): .5, (0, 3): .3, (0, 4): .7, (0, 5): .9, (1, 2): .4, (1, 3): .6, (1, 4): .2,
             (1, 5): .8, (2, 3): .35, (2, 4): .45, (2, 5): .15, (3, 4): .25, (3, 5): .55, (4, 5): .65}
    D = np.zeros((6, 6))
    for (i, j), v in upper.items():
        D[i, j] = D[j, i] = v
    return D, np.array([0, 0, 0, 1, 1, 1])


def test_ranked_lists_remove_the_query():
    D, _ = six_items()
    expected = [[1, 3, 2, 4, 5], [0, 4, 2, 3, 5], [5, 3, 1, 4, 0],
                [4, 0, 2, 5, 1], [1, 3, 2, 5, 0], [2, 3, 4, 1, 0]]
    np.testing.assert_array_equal(ranked_lists(D), expected)


def test_hand_computed_six_items():
    # C = 3, so R = 2 relevant items per query among N = 5; FT looks at the top 2, ST at the top 4,
    # E at the top min(32, 5) = 5; ideal DCG = 1 + 1 = 2.
    D, labels = six_items()
    m = retrieval_metrics(D, labels)
    np.testing.assert_array_equal(m.nn, [1, 1, 0, 1, 0, 0])
    np.testing.assert_allclose(m.first_tier, [.5, .5, 0, .5, .5, .5])
    np.testing.assert_allclose(m.second_tier, [1, 1, .5, 1, 1, 1])
    # all R = 2 relevant items are within the top 5: E = 2 / (1/P + 1/R) = 2 * 2 / (5 + 2)
    np.testing.assert_allclose(m.e_measure, np.full(6, 4 / 7))
    dcg = np.array([1 + W3, 1 + W3, W3 + W5, 1 + W4, 1 + W4, 1 + W3]) / 2
    np.testing.assert_allclose(m.dcg, dcg)
    # AP: mean precision at the ranks of the relevant items
    ap = [(1 + 2 / 3) / 2, (1 + 2 / 3) / 2, (1 / 3 + 2 / 5) / 2, (1 + 2 / 4) / 2, (1 / 2 + 2 / 4) / 2,
          (1 / 2 + 2 / 3) / 2]
    np.testing.assert_allclose(m.average_precision, ap)
    assert m.micro["nn"] == pytest.approx(0.5)
    assert m.micro["first_tier"] == pytest.approx(2.5 / 6)
    assert m.micro["second_tier"] == pytest.approx(5.5 / 6)
    assert m.micro["dcg"] == pytest.approx(dcg.mean())
    assert m.micro["map"] == pytest.approx(np.mean(ap))
    # equal class sizes: macro = micro
    for k in METRIC_NAMES:
        assert m.macro[k] == pytest.approx(m.micro[k])
    np.testing.assert_array_equal(m.class_size, 3)
    assert m.evaluated.all()


def test_e_measure_with_a_short_cutoff():
    # top 2: hits 1 1 0 1 1 1; P = h / 2, R = h / 2, E = h / 2
    D, labels = six_items()
    m = retrieval_metrics(D, labels, e_cutoff=2)
    np.testing.assert_allclose(m.e_measure, [.5, .5, 0, .5, .5, .5])


def test_interpolated_precision_recall_by_hand():
    D, labels = six_items()
    m = retrieval_metrics(D, labels, recall_steps=10)
    np.testing.assert_allclose(m.recall_levels, np.arange(11) / 10)
    # q3: G = 1 0 0 1 0, precision 1, 1/2, 1/3, 2/4, 2/5: recall <= 0.5 reached at rank 1 (P 1),
    # recall > 0.5 needs both hits (rank 4), best precision from there on 0.5
    np.testing.assert_allclose(m.precision_at_recall[3], [1] * 6 + [.5] * 5)
    # q0: G = 1 0 1 0 0: 1 up to recall 0.5, then max(2/3, 2/4, 2/5) = 2/3
    np.testing.assert_allclose(m.precision_at_recall[0], [1] * 6 + [2 / 3] * 5)
    # q2: G = 0 0 1 0 1: precision 0, 0, 1/3, 1/4, 2/5; the max from any rank on is 2/5
    np.testing.assert_allclose(m.precision_at_recall[2], np.full(11, 0.4))
    # q4: G = 0 1 0 1 0 -> 1/2 everywhere; q5: G = 0 1 1 0 0 -> 2/3 everywhere
    np.testing.assert_allclose(m.precision_at_recall[4], np.full(11, 0.5))
    np.testing.assert_allclose(m.precision_at_recall[5], np.full(11, 2 / 3))
    np.testing.assert_allclose(m.micro_pr, m.precision_at_recall.mean(axis=0))
    rec, prec = precision_recall(D, labels, recall_steps=10)
    np.testing.assert_allclose(rec, m.recall_levels)
    np.testing.assert_allclose(prec, m.micro_pr)


def test_default_recall_levels_are_twenty_one():
    D, labels = six_items()
    rec, prec = precision_recall(D, labels)
    np.testing.assert_allclose(rec, np.linspace(0, 1, 21))
    assert prec.shape == (21,)


def test_ties_follow_item_order_and_micro_differs_from_macro():
    # all dissimilarities equal: every list is in index order. Classes A = {0,1,2} (R = 2), B = {3..6} (R = 3).
    labels = np.array([0, 0, 0, 1, 1, 1, 1])
    m = retrieval_metrics(np.zeros((7, 7)), labels)
    np.testing.assert_array_equal(ranked_lists(np.zeros((7, 7)))[4], [0, 1, 2, 3, 5, 6])
    # A queries see their two classmates first; B queries see A first, then their three classmates.
    np.testing.assert_array_equal(m.nn, [1, 1, 1, 0, 0, 0, 0])
    np.testing.assert_array_equal(m.first_tier, [1, 1, 1, 0, 0, 0, 0])
    np.testing.assert_array_equal(m.second_tier, np.ones(7))  # B: top min(6, 6) holds all 3
    ap_b = (1 / 4 + 2 / 5 + 3 / 6) / 3
    np.testing.assert_allclose(m.average_precision, [1, 1, 1] + [ap_b] * 4)
    dcg_b = (W4 + W5 + W6) / (1 + 1 + W3)
    np.testing.assert_allclose(m.dcg, [1, 1, 1] + [dcg_b] * 4)
    np.testing.assert_allclose(m.e_measure, [2 * 2 / (6 + 2)] * 3 + [2 * 3 / (6 + 3)] * 4)
    assert m.micro["nn"] == pytest.approx(3 / 7)
    assert m.macro["nn"] == pytest.approx(0.5)
    assert m.micro["map"] == pytest.approx((3 + 4 * ap_b) / 7)
    assert m.macro["map"] == pytest.approx((1 + ap_b) / 2)
    assert m.per_class[1]["size"] == 4
    assert m.per_class[1]["dcg"] == pytest.approx(dcg_b)


def test_psb_float32_rounding_creates_psbtables_ties():
    # D[0, 2] is below D[0, 1] in float64 but equal in float32: psbTable then lists item 1 first
    D = np.array([[0.0, 0.5, 0.5 - 1e-12], [0.5, 0.0, 0.7], [0.5 - 1e-12, 0.7, 0.0]])
    assert ranked_lists(D)[0].tolist() == [2, 1]
    assert ranked_lists(D, psb_float32=True)[0].tolist() == [1, 2]


def test_the_query_is_removed_even_when_its_self_distance_is_not_smallest():
    D, labels = six_items()
    D2 = D.copy()
    np.fill_diagonal(D2, [5.0, -1.0, np.inf, 0.3, 0.0, -np.inf])
    for i, row in enumerate(ranked_lists(D2)):
        assert i not in row
    np.testing.assert_array_equal(ranked_lists(D2), ranked_lists(D))


def test_each_row_is_its_own_ranked_list():
    # an asymmetric D: only row i matters for query i
    D, labels = six_items()
    D2 = D.copy()
    D2[0] = [0, 9, 1, 8, 7, 2]  # q0: 2 5 4 3 1 -> G = 1 0 0 0 1
    m = retrieval_metrics(D2, labels)
    assert m.nn[0] == 1 and m.first_tier[0] == 0.5 and m.second_tier[0] == 0.5
    np.testing.assert_allclose(m.nn[1:], retrieval_metrics(D, labels).nn[1:])


def test_perfect_matrix_scores_one():
    rng = np.random.default_rng(3)
    labels = rng.permutation(np.repeat(np.arange(5), [3, 6, 10, 40, 41]))
    same = labels[:, None] == labels[None, :]
    D = np.where(same, rng.random(same.shape) * 0.5, 1.0 + rng.random(same.shape))
    m = retrieval_metrics(D, labels)
    for name in ("nn", "first_tier", "second_tier", "dcg", "map"):
        np.testing.assert_allclose(m.per_query()[name], 1.0, err_msg=name)
        assert m.micro[name] == pytest.approx(1.0) and m.macro[name] == pytest.approx(1.0)
    np.testing.assert_allclose(m.precision_at_recall, 1.0)
    # E is bounded by 2 min(R, K) / (K + R): 1 only when R = K = 32
    R = m.class_size - 1
    np.testing.assert_allclose(m.e_measure, 2 * np.minimum(R, 32) / (32 + R))


def test_random_matrix_gives_chance_levels():
    # each row of a random D is a uniformly random ranking: the averages approach the exact
    # expectations of chance_levels (2000 queries: standard error <= 0.01 for every metric)
    rng = np.random.default_rng(11)
    labels = np.repeat(np.arange(4), 50)
    runs = [retrieval_metrics(rng.random((200, 200)), labels).micro for _ in range(10)]
    chance = chance_levels(labels)["micro"]
    assert chance["nn"] == pytest.approx(49 / 199)
    assert chance["second_tier"] == pytest.approx(98 / 199)
    for name in METRIC_NAMES:
        assert np.mean([r[name] for r in runs]) == pytest.approx(chance[name], abs=0.03), name


def test_small_classes_and_ignored_labels_leave_the_averages():
    # psbTable: classes of <= 2 models are not averaged; they still occupy ranks
    labels = np.array(["a", "a", "a", "b", "b", "c", "m", "m", "m"])
    rng = np.random.default_rng(0)
    D = rng.random((9, 9))
    m = retrieval_metrics(D, labels, ignore_labels=["m"])
    np.testing.assert_array_equal(m.evaluated, [1, 1, 1, 0, 0, 0, 0, 0, 0])
    assert set(m.per_class) == {"a"}
    assert m.micro["nn"] == pytest.approx(m.nn[:3].mean())
    assert m.macro["dcg"] == pytest.approx(m.dcg[:3].mean())
    # a singleton class scores 0 (no relevant item)
    assert m.nn[5] == 0 and m.dcg[5] == 0 and m.average_precision[5] == 0 and m.e_measure[5] == 0
    everyone = retrieval_metrics(D, labels, min_class_size=1)
    assert everyone.evaluated.all()
    assert set(everyone.per_class) == {"a", "b", "c", "m"}


def test_blocked_computation_matches_one_block(monkeypatch):
    rng = np.random.default_rng(5)
    labels = rng.integers(0, 6, 150)
    D = rng.random((150, 150))
    D[rng.random(D.shape) < 0.3] = 0.5  # plenty of ties
    whole = retrieval_metrics(D, labels)
    monkeypatch.setattr(metrics_module, "_BLOCK_ENTRIES", 7 * 150)  # 7 rows per block
    blocked = retrieval_metrics(D, labels)
    for name in METRIC_NAMES:
        np.testing.assert_allclose(blocked.per_query()[name], whole.per_query()[name], rtol=1e-13)  # BLAS sums
    np.testing.assert_array_equal(blocked.precision_at_recall, whole.precision_at_recall)
    np.testing.assert_array_equal(ranked_lists(D), np.argsort(np.where(np.eye(150, dtype=bool), np.inf, D),
                                                              axis=1, kind="stable")[:, :-1])


def test_as_dict_and_table():
    D, labels = six_items()
    m = retrieval_metrics(D, labels)
    d = m.as_dict()
    assert d["micro"]["nn"] == 0.5 and len(d["micro_pr"]) == 21 and d["e_cutoff"] == 5
    assert "| NN |" in m.table("d2") and m.table("d2").count("\n") == 3
    assert m.precision_recall("macro").precision.shape == (21,)


@pytest.mark.parametrize("D, labels, match", [
    (np.zeros((3, 4)), [0, 0, 1], "square"),
    (np.zeros((1, 1)), [0], "at least 2"),
    (np.array([[0, np.nan], [1, 0]]), [0, 0], "NaN"),
    (np.zeros((3, 3)), [0, 1], r"labels must have shape \(3,\)"),
    (np.full((2, 2), "x"), [0, 1], "real numbers"),
])
def test_bad_inputs_are_rejected(D, labels, match):
    with pytest.raises(ValueError, match=match):
        retrieval_metrics(D, labels)


@pytest.mark.parametrize("option", [{"e_cutoff": 0}, {"recall_steps": 0}, {"min_class_size": 0},
                                    {"e_cutoff": 2.5}])
def test_bad_options_are_rejected(option):
    D, labels = six_items()
    with pytest.raises(ValueError, match=next(iter(option))):
        retrieval_metrics(D, labels, **option)


def test_bad_average_is_rejected():
    D, labels = six_items()
    with pytest.raises(ValueError, match="micro"):
        precision_recall(D, labels, average="weighted")
