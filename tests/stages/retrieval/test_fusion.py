"""Fusion of dissimilarities and manifold ranking (Zhou et al. 2004)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from topomatch.stages.retrieval.catalogue import get_method
from topomatch.stages.retrieval.fusion import Fusion, fuse, fused_matrix, fused_query, manifold_ranking, median_scale


def two_moons(n=60, seed=0):
    """Two interleaved half circles: the nearest points of the other moon are closer than the far end of one's own."""
    t = np.linspace(0, np.pi, n)
    a = np.column_stack([np.cos(t), np.sin(t)])
    b = np.column_stack([1 - np.cos(t), 0.5 - np.sin(t)])
    X = np.vstack([a, b]) + 0.01 * np.random.default_rng(seed).standard_normal((2 * n, 2))
    return X, np.repeat([0, 1], n)


def first_tier(D, y):
    hits = []
    for i in range(len(D)):
        order = [j for j in np.argsort(D[i], kind="stable") if j != i][: (y == y[i]).sum() - 1]
        hits.append(np.mean(y[order] == y[i]))
    return float(np.mean(hits))


def test_manifold_ranking_follows_the_data_manifold():
    X, y = two_moons()
    D = cdist(X, X)
    assert first_tier(D, y) < 0.8  # Euclidean ranking mixes the moons
    R = manifold_ranking(D, k=5, alpha=0.99)
    assert first_tier(R, y) > 0.98
    np.testing.assert_allclose(R, R.T)
    assert R.min() >= 0 and R.max() <= 1


def test_median_scale_and_equal_weights():
    A = np.array([[0, 1, 3], [1, 0, 2], [3, 2, 0]], float)
    assert median_scale(A) == 2.0
    np.testing.assert_allclose(fuse([A, 10 * A], [2.0, 20.0]), A)
    assert median_scale(np.zeros((3, 3))) == 1.0


def test_fused_query_of_a_duplicate_ranks_it_first():
    X, _ = two_moons(30)
    parts = [cdist(X, X), cdist(X, X, "cityblock")]
    q = X[7] + 1e-9
    rows = [cdist(q[None], X)[0], cdist(q[None], X, "cityblock")[0]]
    for k in (None, 5):
        d = fused_query(rows, parts, Fusion(("a", "b"), k, 0.9))
        assert np.argmin(d) == 7 and d.shape == (60,)
    # without re-ranking the fused row is the scaled sum
    d = fused_query(rows, parts, Fusion(("a", "b"), None, 0.9))
    np.testing.assert_allclose(d, rows[0] / median_scale(parts[0]) + rows[1] / median_scale(parts[1]))
    assert fused_matrix(parts, Fusion(("a", "b"), None, 0.9)) == pytest.approx(fuse(parts, [median_scale(p) for p in parts]))


def _uneven(seed=0):
    """Points in classes of very different sizes and densities (3 to 20 points): (n, 4) float64."""
    rng = np.random.default_rng(seed)
    sizes = [3, 20, 4, 12, 3, 8]
    centres = rng.normal(size=(len(sizes), 4)) * 2.5
    return np.vstack([c + rng.normal(size=(s, 4)) * (0.6 if s > 10 else 1.0) for c, s in zip(centres, sizes)])


def test_one_row_ranks_as_the_full_ranking():
    from topomatch.stages.retrieval.fusion import manifold_ranking_row

    for X in (two_moons(40, seed=2)[0], _uneven(1)):
        D = cdist(X, X)
        for beta in (0.0, 0.5, 1.0):
            R = manifold_ranking(D, k=6, alpha=0.9, normalisation=beta)
            for i in (0, 17, 39):
                r = manifold_ranking_row(D, i, k=6, alpha=0.9, normalisation=beta)
                # the same scores up to a positive scale (1 - r is G_i / max G_i)
                np.testing.assert_allclose((1 - r) / (1 - r).max(), (1 - R[i]) / (1 - R[i]).max(), rtol=1e-9,
                                           atol=1e-12)
                assert r[i] == pytest.approx(0.0)


def _query_graph(X, q, parts, fusion):
    """A query point q among the points X (n, d): its parts' rows (Euclidean, city-block), the fusion's
    decision for the (n + 1)-item graph, and that graph's fused (n + 1, n + 1) matrix, the query last."""
    from topomatch.stages.retrieval.fusion import decide, kept_scales

    n = len(X)
    rows = [cdist(q[None], X)[0], cdist(q[None], X, "cityblock")[0]]
    decision = decide(parts, fusion, graph_size=n + 1)
    scales = kept_scales(parts, fusion, decision)
    A = np.zeros((n + 1, n + 1))
    A[:n, :n] = fuse(parts, scales, fusion.order_weights)
    A[n, :n] = A[:n, n] = fuse(rows, scales, fusion.order_weights)
    return rows, decision, A


def test_the_fusions_rank_with_the_normalisation_they_name():
    # fused_matrix and fused_query re-rank by manifold ranking with the fusion's beta (module docstring),
    # and beta changes the ranking of a collection with classes of uneven size and density
    from topomatch.stages.retrieval.fusion import decide, kept_scales, manifold_ranking_row

    X = _uneven(0)
    parts = [cdist(X, X), cdist(X, X, "cityblock")]
    n = len(X)
    plain = Fusion(("a", "b"), "auto", 0.9, order_weights=(1, 1), screen=0.5, agreement_power=1.0)
    tops = {}
    for beta in (0.0, 0.5, 1.0):
        fusion = replace(plain, rerank_normalisation=beta)
        decision = decide(parts, fusion)
        D = fuse(parts, kept_scales(parts, fusion, decision), fusion.order_weights)
        R = fused_matrix(parts, fusion)
        np.testing.assert_allclose(R, manifold_ranking(D, decision.rerank_k, 0.9, beta), atol=1e-12)
        tops[beta] = [tuple(np.argsort(R[i], kind="stable")[:5]) for i in range(n)]
        # one query (a point between two classes): its row of the (n + 1)-item graph
        q = (X[1] + X[10]) / 2
        rows, query_decision, A = _query_graph(X, q, parts, fusion)
        d = fused_query(rows, parts, fusion, query_decision)
        ref = manifold_ranking_row(A, n, query_decision.rerank_k, 0.9, beta)[:n]
        reached = ref < 1  # the items the diffusion reaches keep their re-ranked values; the others follow them,
        np.testing.assert_allclose(d[reached], ref[reached], atol=1e-12)  # in the order of the fused row
        assert reached.any() and (d[~reached] >= 1).all() and (d[~reached] < 2).all()
        far = np.flatnonzero(~reached)
        assert (np.argsort(d[far], kind="stable") == np.argsort(A[n, far], kind="stable")).all()
    assert sum(a != b for a, b in zip(tops[0.0], tops[1.0])) >= 3


def test_a_query_gets_the_values_the_collection_matrix_would_give_it():
    # with the default normalisation (beta = 1/2) a query's re-ranked values are its row of the (n + 1)-item
    # matrix, 1 - the cosine of the diffusion states: its first match is 0 only for a duplicate, not whenever
    # it is the database's best (the values said how far a match is, not only its rank)
    X = _uneven(1)
    parts = [cdist(X, X), cdist(X, X, "cityblock")]
    n = len(X)
    fusion = Fusion(("a", "b"), "auto", 0.95, order_weights=(1, 1), rerank_normalisation=0.5)
    for q in ((X[1] + X[10]) / 2, X[3] + 0.05, X[3]):
        rows, decision, A = _query_graph(X, q, parts, fusion)
        d = fused_query(rows, parts, fusion, decision)
        duplicate = rows[0] == 0  # put first at 0 by fused_query (the diffusion need not score it first)
        np.testing.assert_allclose(d[~duplicate], manifold_ranking(A, decision.rerank_k, 0.95, 0.5)[n, :n][~duplicate],
                                   atol=1e-12)
        assert (d[duplicate] == 0).all() and (d[~duplicate] > 1e-9).all()
    # an outlier, far from every point: the diffusion's scores fall below round-off, so its values are its fused
    # dissimilarities mapped to [1, 2), in their order (they used to be the raw fused values, on another scale)
    rows, decision, A = _query_graph(X, X.mean(axis=0) + 1e3, parts, fusion)
    d = fused_query(rows, parts, fusion, decision)
    assert (d >= 1).all() and (d < 2).all()
    assert (np.argsort(d, kind="stable") == np.argsort(A[n, :n], kind="stable")).all()


def test_half_normalised_scores_are_cosines_of_the_diffusion_states():
    # F = (I - alpha S)^-1 is positive definite, so F_ij / sqrt(F_ii F_jj) is a cosine: at most 1, and 1 on the
    # diagonal only (Cauchy-Schwarz); the ranking is therefore 0 on the diagonal, in [0, 1] and symmetric
    X, _ = two_moons(30, seed=5)
    R = manifold_ranking(cdist(X, X), k=5, alpha=0.9, normalisation=0.5)
    np.testing.assert_allclose(np.diag(R), 0.0, atol=1e-12)
    off = R[~np.eye(len(R), dtype=bool)]
    assert off.min() > 0 and R.max() <= 1
    np.testing.assert_allclose(R, R.T, atol=1e-12)


def _scrambled(D, seed):
    """The same dissimilarities attached to the wrong shapes: no class information, same distribution."""
    perm = np.random.default_rng(seed).permutation(len(D))
    return D[np.ix_(perm, perm)]


def _clusters(n_classes=6, per=8, seed=0):
    rng = np.random.default_rng(seed)
    centres = rng.normal(size=(n_classes, 4)) * 3
    X = np.repeat(centres, per, axis=0) + rng.normal(size=(n_classes * per, 4))
    return X, np.repeat(np.arange(n_classes), per)


def test_agreement_is_one_for_copies_and_near_chance_for_a_scrambled_part():
    from topomatch.stages.retrieval.fusion import agreement

    X, _ = _clusters()
    D = cdist(X, X)
    np.testing.assert_allclose(agreement([D, 2 * D, D ** 2]), 1.0)
    a = agreement([D, cdist(X, X, "cityblock"), _scrambled(D, 1)])
    chance = 5 / (len(D) - 1)
    assert a[0] > 0.5 and a[1] > 0.5 and a[2] < 3 * chance


def test_screening_drops_parts_without_class_information_and_keeps_the_ranking():
    from topomatch.stages.retrieval.fusion import decide

    X, y = _clusters()
    good = [cdist(X, X), cdist(X, X, "cityblock")]
    junk = [_scrambled(good[0], 1), _scrambled(good[1], 2)]
    fusion = Fusion(("a", "b", "c", "d"), None, 0.9, order_weights=(1, 1, 0.5, 0.25), screen=0.5)
    decision = decide(good + junk, fusion)
    assert decision.kept == ("a", "b") and decision.dropped == ("c", "d")
    screened = fused_matrix(good + junk, fusion)
    np.testing.assert_allclose(screened, fused_matrix(good, fusion.with_parts(("a", "b"))))
    unscreened = fused_matrix(good + junk, Fusion(("a", "b", "c", "d"), None, 0.9))
    assert first_tier(screened, y) > first_tier(unscreened, y)
    # every part is kept when all of them see the classes
    assert decide(good + [cdist(X, X, "chebyshev")], fusion.with_parts("abc")).dropped == ()


def test_order_weights_give_the_minimum_the_mean_and_ignore_the_order_of_parts():
    A = np.array([[0, 1, 4], [1, 0, 2], [4, 2, 0]], float)
    B = np.array([[0, 3, 1], [3, 0, 5], [1, 5, 0]], float)
    np.testing.assert_allclose(fuse([A, B], [1, 1], (1, 0)), np.minimum(A, B))
    np.testing.assert_allclose(fuse([A, B], [1, 1], (1, 1)), (A + B) / 2)
    np.testing.assert_allclose(fuse([A, B], [1, 1], (3, 1)), fuse([B, A], [1, 1], (3, 1)))
    np.testing.assert_allclose(fuse([A, B], [1, 1], (1, 1, 1)), (A + B) / 2)  # truncated to the parts


def test_automatic_rerank_neighbours_follow_the_collection_size():
    from topomatch.stages.retrieval.fusion import rerank_neighbours

    auto = Fusion(("a",), "auto", 0.9)
    assert [rerank_neighbours(auto, n) for n in (4, 100, 400, 10_000)] == [3, 5, 10, 50]
    assert rerank_neighbours(Fusion(("a",), 7, 0.9), 400) == 7 and rerank_neighbours(Fusion(("a",), None, 0.9), 9) is None


def test_adaptive_query_of_a_duplicate_ranks_it_first_and_agrees_with_the_collection_ranking():
    X, _ = _clusters(seed=3)
    parts = [cdist(X, X), cdist(X, X, "cityblock"), _scrambled(cdist(X, X), 4)]
    fusion = Fusion(("a", "b", "c"), "auto", 0.9, order_weights=(1, 1, 0.5), screen=0.5)
    i = 11
    rows = [P[i] for P in parts]
    d = fused_query(rows, parts, fusion)
    assert np.argmin(d) == i and d[i] == 0.0
    R = fused_matrix(parts, fusion)
    top = lambda r: set(np.argsort(r, kind="stable")[:6])  # noqa: E731
    assert len(top(d) & top(R[i])) >= 5


def test_agreement_weighting_pushes_parts_without_class_information_out_of_the_two_smallest():
    from topomatch.stages.retrieval.fusion import decide, scale_factor

    X, y = _clusters()
    good = [cdist(X, X), cdist(X, X, "cityblock")]
    junk = [_scrambled(good[0], 1), _scrambled(good[1], 2)]
    weighted = Fusion(("a", "b", "c", "d"), None, 0.9, order_weights=(1, 1), agreement_power=4.0)
    decision = decide(good + junk, weighted)
    assert decision.kept == ("a", "b", "c", "d") and decision.dropped == ()  # weighted, not dropped
    factors = [scale_factor(weighted, decision, p) for p in "abcd"]
    assert max(factors) == 1.0 and max(factors[2:]) < 0.05 * min(factors[:2])  # chance-level agreement
    # the junk parts then almost never enter a pair's two smallest: the ranking is the good parts'
    alone = fused_matrix(good, Fusion(("a", "b"), None, 0.9, order_weights=(1, 1)))
    mixed = fused_matrix(good + junk, weighted)
    assert first_tier(mixed, y) >= first_tier(alone, y) - 0.02
    assert first_tier(mixed, y) > first_tier(fused_matrix(good + junk, replace(weighted, agreement_power=0.0)), y)
    # a query ranks as the collection does
    i = 7
    d = fused_query([P[i] for P in good + junk], good + junk, replace(weighted, rerank_k="auto"))
    R = fused_matrix(good + junk, replace(weighted, rerank_k="auto"))
    assert np.argmin(d) == i
    assert len(set(np.argsort(d, kind="stable")[:6]) & set(np.argsort(R[i], kind="stable")[:6])) >= 5


def test_order_weighted_fusion_equals_the_sorted_stack_formula():
    rng = np.random.default_rng(5)
    parts = [rng.random((30, 30)) for _ in range(5)]
    parts[2][3, 4] = np.inf
    parts[1][:5] = parts[0][:5]  # ties
    for w in ((1, 1), (1, 1, 0.5, 0.25, 0.1), (2, 1, 1)):
        stack = np.sort(np.stack([P / s for P, s in zip(parts, (1, 2, 3, 4, 5))]), axis=0)[: len(w)]
        expected = np.tensordot(np.asarray(w) / sum(w), stack, axes=1)
        np.testing.assert_array_equal(fuse(parts, [1, 2, 3, 4, 5], w), expected)
    parts[4][0, 0] = np.nan  # the sorted-stack path: NaN last
    assert np.isfinite(fuse(parts, [1] * 5, (1, 1))[0, 0])


def test_an_item_identical_to_the_query_ranks_first_even_on_a_tiny_graph():
    # small random collections where the diffusion alone scores a well-connected neighbour of the
    # query above the query's own copy (seeds 0, 5, 7 did before the fix)
    for seed in range(10):
        r = np.random.default_rng(seed)
        n = int(r.integers(6, 14))
        X = r.random((n, 3)) * r.uniform(0.2, 1, (1, 3))
        parts = [cdist(X, X), cdist(X, X, "cityblock")]
        for beta in (0.0, 0.5, 1.0):
            fusion = Fusion(("a", "b"), "auto", 0.9, order_weights=(1, 1), agreement_power=4.0,
                            rerank_normalisation=beta)
            for q in range(n):
                d = fused_query([P[q] for P in parts], parts, fusion)
                assert d[q] == 0.0 and (np.delete(d, q) > 0).all(), (seed, q, beta)


def test_exact_duplicates_give_finite_rankings():
    # four identical shapes and two others: the k-th neighbour distance of a copy is 0
    X = np.array([[0.0, 0.0]] * 4 + [[1.0, 0.0], [0.0, 2.0]])
    D = cdist(X, X)
    for k in (1, 3, 5):
        for beta in (0.0, 0.5, 1.0):
            R = manifold_ranking(D, k, normalisation=beta)
            assert np.isfinite(R).all() and R.min() >= 0 and R.max() <= 1
    _check_duplicates(Fusion(("a", "b"), "auto", 0.9, order_weights=(1, 1), agreement_power=4.0), D)
    _check_duplicates(get_method("topomatch").fusion.with_parts(("a", "b")), D)


def _check_duplicates(fusion, D):
    """The fusion on exact duplicates: finite rankings, copies of the query first and tied."""
    F = fused_matrix([D, 2 * D], fusion)
    assert np.isfinite(F).all()
    d = fused_query([D[0], 2 * D[0]], [D, 2 * D], fusion)
    assert np.isfinite(d).all() and (d[:4] == 0).all() and (d[4:] > 0).all()
    zeros = np.zeros((5, 5))  # every shape identical
    assert np.isfinite(fused_matrix([zeros, zeros], fusion)).all()
    # a query unlike four identical database shapes: finite, and the copies tie
    D5 = np.zeros((4, 4))
    d = fused_query([np.full(4, 2.0), np.full(4, 3.0)], [D5, D5], fusion)
    assert np.isfinite(d).all() and np.ptp(d) <= 1e-12  # tied up to the round-off of the inverse


# --- agreement rules (issue 29) ---------------------------------------------------------------------------------


def _agreement_before_issue_29(part_matrices, k=5):
    """The screening's agreement as it was before ``Fusion.agreement_rule`` existed (copied from the git history)."""
    n = len(part_matrices[0])
    if len(part_matrices) < 2 or n < 3:
        return np.ones(len(part_matrices))
    k = min(k, n - 1)
    sets = []
    for P in part_matrices:
        D = np.array(P, dtype=np.float64)
        D[~np.isfinite(D)] = np.inf
        np.fill_diagonal(D, np.inf)
        sets.append(np.argpartition(D, k - 1, axis=1)[:, :k])
    pair = np.array([[(a[:, :, None] == b[:, None, :]).sum() / (n * k) for b in sets] for a in sets])
    return (pair.sum(axis=1) - np.diag(pair)) / (len(sets) - 1)


def _camps(seed=0):
    """Three informative parts (one class structure, each with its own noise) and a *camp* of two parts that agree
    with each other almost perfectly and carry no class information (both measure one random embedding): the
    shape of D2 and spherical harmonics on real poses, which agree with each other and not with the classes."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.arange(8), 10)
    X = (rng.normal(size=(8, 6)) * 3)[y] + rng.normal(size=(len(y), 6))
    sym = lambda D: (D + D.T) / 2  # noqa: E731
    good = [sym(cdist(X + 0.5 * rng.normal(size=X.shape), X)) for _ in range(3)]
    Z = rng.normal(size=(len(y), 3))
    camp = [sym(cdist(Z + 0.02 * rng.normal(size=Z.shape), Z)) for _ in range(2)]
    return good, camp, y


def _map(D, y):
    from topomatch.stages.retrieval.metrics import retrieval_metrics

    return retrieval_metrics(D, y).micro["map"]


def test_the_mean_rule_is_the_screening_of_before_bit_for_bit():
    from topomatch.stages.retrieval.fusion import FusionDecision, agreement, decide, rerank_neighbours

    good, camp, _ = _camps(seed=2)
    mats = good + camp
    for m in (mats, mats[:2], [good[0], np.where(good[1] > np.median(good[1]), np.inf, good[1])]):
        assert np.array_equal(agreement(m), _agreement_before_issue_29(m))
    default = get_method("topomatch").fusion
    for fusion in (replace(default, agreement_rule="mean"), replace(default, agreement_rule="mean", screen=0.65)):
        a = _agreement_before_issue_29(mats)
        keep = a >= fusion.screen * a.max()
        before = FusionDecision(tuple(p for p, k in zip(fusion.parts, keep) if k),
                                tuple(p for p, k in zip(fusion.parts, keep) if not k),
                                {p: float(x) for p, x in zip(fusion.parts, a)}, rerank_neighbours(fusion, len(mats[0])))
        assert decide(mats, fusion) == before
        assert np.array_equal(fused_matrix(mats, fusion), fused_matrix(mats, fusion, before))
    # the catalogue's methods keep a valid rule, and an unknown one is refused
    assert default.agreement_rule in ("mean", "consensus", "iterative")
    with pytest.raises(ValueError, match="agreement_rule"):
        replace(default, agreement_rule="median")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_iterative_rule_drops_a_camp_without_class_information_that_the_mean_rule_keeps(seed):
    from topomatch.stages.retrieval.fusion import agreement, decide

    good, camp, y = _camps(seed)
    mats = good + camp
    parts = ("agd", "hks", "shapedna", "d2", "sh")
    fusion = Fusion(parts, "auto", 0.95, order_weights=(1, 1), screen=0.5, rerank_normalisation=0.5)
    # the failure of issue 29: each part of the camp agrees with its partner, so its mean agreement passes the screen
    a = agreement(mats)
    assert a[3:].min() >= 0.5 * a.max()
    assert decide(mats, fusion).dropped == ()
    iterative = replace(fusion, agreement_rule="iterative")
    decision = decide(mats, iterative)
    assert decision.kept == parts[:3] and decision.dropped == parts[3:]  # weight 0: not in the fusion at all
    # the fused ranking is then exactly that of the informative parts alone
    alone = fused_matrix(good, replace(fusion, parts=parts[:3], screen=None))
    fused = fused_matrix(mats, iterative)
    assert np.array_equal(fused, alone)
    assert _map(fused, y) == _map(alone, y) > _map(fused_matrix(mats, fusion), y)


def test_rules_keep_every_part_when_all_of_them_see_the_classes_and_a_lone_junk_part_goes_by_every_rule():
    from topomatch.stages.retrieval.fusion import decide

    X, _ = _clusters()
    informative = [cdist(X, X), cdist(X, X, "cityblock"), cdist(X, X, "chebyshev")]
    lone = informative + [_scrambled(informative[0], 5)]
    for rule in ("mean", "consensus", "iterative"):
        fusion = Fusion(("a", "b", "c"), "auto", 0.95, order_weights=(1, 1), screen=0.5, agreement_rule=rule)
        assert decide(informative, fusion).dropped == ()
        assert decide(lone, fusion.with_parts("abcd")).dropped == ("d",)
