"""The thesis page's checks can fail: each verdict is computed from the run's tables, so tables built to
contradict the thesis's sentence must give ``differs`` (or ``partly``), and tables that agree with it
``reproduced`` -- a check that could not fail would be a claim true by construction."""

from __future__ import annotations

import json

from topomatch import thesis


def _runs(tmp_path, config: str, tables: dict[str, list[dict]]) -> dict:
    run = tmp_path / config.replace("/", "_")
    (run / "tables").mkdir(parents=True, exist_ok=True)
    for name, rows in tables.items():
        (run / "tables" / f"{name}.json").write_text(json.dumps(rows))
    return {config: run}


def _recovery_rows(tre: dict[str, list[float]]) -> list[dict]:
    return [{"input": "img", "method": f"spsa/{m}(alpha=2)", "true_tx": 5.0, "seed": k, "tre_mean": v}
            for m, values in tre.items() for k, v in enumerate(values)]


def test_most_accurate_needs_a_margin_beyond_the_seed_spread(tmp_path):
    clear = {"jt": [0.01, 0.011, 0.012], "mi": [0.05, 0.051, 0.052], "jr": [0.06, 0.06, 0.061]}
    runs = _runs(tmp_path, "registration/recovery", {"fig2_6_to_2_8": _recovery_rows(clear)})
    assert thesis._recovery(runs)[0] == "reproduced"
    within = {"jt": [0.01, 0.03, 0.05], "mi": [0.02, 0.03, 0.04], "jr": [0.06, 0.06, 0.061]}  # JT lowest, not beyond
    runs = _runs(tmp_path / "b", "registration/recovery", {"fig2_6_to_2_8": _recovery_rows(within)})
    assert thesis._recovery(runs)[0] == "differs"
    one_seed = {"jt": [0.01], "mi": [0.05]}  # no spread measured: no verdict of "best"
    runs = _runs(tmp_path / "c", "registration/recovery", {"fig2_6_to_2_8": _recovery_rows(one_seed)})
    assert thesis._recovery(runs)[0] == "differs"


def _curves(pair: str, maxima: list[float], peak: float = 0.0, sharp: float = 0.2) -> list[dict]:
    return [{"input": pair, "parameter": p, "alpha": a, "max": m, "peak_at": peak, "mean_over_max": sharp}
            for p in ("angle", "tx") for a, m in zip((0.5, 1.0, 2.0), maxima)]


def test_the_landscape_sentences_are_judged_on_the_pair_of_two_images_only(tmp_path):
    check = thesis._landscape("jr_h", "jr")
    same = _curves("T1|PD", [1.0, 1.0, 1.0])
    runs = _runs(tmp_path, "registration/landscapes", {"jr_h": _curves("PD|PD", [3.0, 2.0, 1.0]) + same})
    assert check(runs)[0] == "reproduced"  # the self-pair's falling maximum is by construction: not counted
    runs = _runs(tmp_path / "b", "registration/landscapes", {"jr_h": _curves("T1|PD", [1.2, 1.0, 0.9])})
    assert check(runs)[0] == "partly"  # peaks hold, "the same maximum for every alpha" does not
    runs = _runs(tmp_path / "c", "registration/landscapes", {"jr_h": _curves("T1|PD", [1.2, 1.0, 0.9], peak=3.0)})
    assert check(runs)[0] == "differs"
    jt = thesis._landscape("jt_u", "jt", histogram_twin="jt_h")
    runs = _runs(tmp_path / "d", "registration/landscapes", {"jt_u": _curves("T1|PD", [3.0, 1.0, 0.1], sharp=0.1),
                                                             "jt_h": _curves("T1|PD", [3.0, 1.0, 0.1], sharp=0.3)})
    assert jt(runs)[0] == "partly"  # every tested sentence holds, but JT's alpha sentence cannot fail: at most partly
    runs = _runs(tmp_path / "e", "registration/landscapes", {"jt_u": _curves("T1|PD", [3.0, 1.0, 0.1], sharp=0.4),
                                                             "jt_h": _curves("T1|PD", [3.0, 1.0, 0.1], sharp=0.3)})
    verdict, reason = jt(runs)
    assert verdict == "partly" and "in 0 of 6 curves" in reason  # not sharper than histogram weights: 1 of 2 held
    runs = _runs(tmp_path / "e2", "registration/landscapes",
                 {"jt_u": _curves("T1|PD", [3.0, 1.0, 0.1], peak=2.0, sharp=0.4),
                  "jt_h": _curves("T1|PD", [3.0, 1.0, 0.1], sharp=0.3)})
    assert jt(runs)[0] == "differs"  # off the peak and not sharper: the falling maximum does not rescue it
    rising = _runs(tmp_path / "f", "registration/landscapes", {"jt_u": _curves("T1|PD", [0.1, 1.0, 3.0], sharp=0.1),
                                                               "jt_h": _curves("T1|PD", [0.1, 1.0, 3.0], sharp=0.3)})
    verdict, reason = jt(rising)
    assert verdict == "partly" and "does not fall" in reason  # reported, never counted
    self_only = _runs(tmp_path / "g", "registration/landscapes", {"jr_h": _curves("PD|PD", [1.0, 1.0, 1.0], peak=3.0)
                                                                  + _curves("T1|PD", [1.0, 1.0, 1.0])})
    assert check(self_only)[0] == "reproduced"  # an image with itself off its peak is not counted either


def test_endpoints_are_counted_against_the_protrusions(tmp_path):
    rows = [{"item": "odedstein_human_man.obj.gz[morse.function=mixture]", "prune.endpoints": 5},
            {"item": "odedstein_cat-low-resolution.obj.gz[morse.function=mixture]", "prune.endpoints": 6},
            {"item": "odedstein_cat-low-resolution.obj.gz[morse.function=fiedler]", "prune.endpoints": 3}]
    runs = _runs(tmp_path, "skeleton_gallery", {"skeletons": rows})
    assert thesis._one_per_protrusion("mixture", (("skeleton_gallery", "skeletons"),))(runs)[0] == "reproduced"
    verdict, reason = thesis._one_per_protrusion("fiedler", (("skeleton_gallery", "skeletons"),))(runs)
    assert verdict == "differs" and "cat 3 for 6" in reason
    # a model without protrusions is no limb matched: 0 endpoints on the double torus does not lift 1 of 2 to "half"
    rows = [{"item": "eight_genus2.off[morse.function=fiedler]", "prune.endpoints": 0},
            {"item": "odedstein_cat-low-resolution.obj.gz[morse.function=fiedler]", "prune.endpoints": 3},
            {"item": "odedstein_human_man.obj.gz[morse.function=fiedler]", "prune.endpoints": 5},
            {"item": "odedstein_hand_closed.obj.gz[morse.function=fiedler]", "prune.endpoints": 5}]
    runs = _runs(tmp_path / "b", "skeleton_gallery", {"skeletons": rows})
    verdict, reason = thesis._one_per_protrusion("fiedler", (("skeleton_gallery", "skeletons"),))(runs)
    assert verdict == "differs" and "1 of 3 models with protrusions" in reason and "not counted" in reason


def test_the_mixture_is_more_faithful_only_if_nearer_on_most_limbed_models(tmp_path):
    def rows(mixture: dict[str, int], affine: dict[str, int]) -> list[dict]:
        return [{"item": f"{m}.obj.gz[morse.function={f}]", "prune.endpoints": e}
                for f, counts in (("mixture", mixture), ("affine", affine)) for m, e in counts.items()]
    limbs = {"odedstein_human_man": 5, "odedstein_cat-low-resolution": 6, "odedstein_hand_closed": 6}
    cases = [({**limbs, "eight_genus2": 0}, {**{m: e + 1 for m, e in limbs.items()}, "eight_genus2": 0}, "reproduced"),
             ({**limbs, "odedstein_human_man": 6, "eight_genus2": 0},  # nearer on 1 of 3, tied on 2: fewer in total
              {**limbs, "odedstein_human_man": 8, "eight_genus2": 9}, "partly"),
             ({**limbs, "eight_genus2": 4}, {**limbs, "eight_genus2": 12}, "differs")]  # only the double torus differs
    for k, (mixture, affine, verdict) in enumerate(cases):
        runs = _runs(tmp_path / str(k), "skeleton_gallery", {"skeletons": rows(mixture, affine)})
        assert thesis._mixture_vs_affine(runs)[0] == verdict, k


def test_what_holds_by_construction_is_never_reproduced(tmp_path):
    """Cycles = genus with the band splitting, and an image's conditionals against itself: reported, not counted."""
    steps = [{"item": "eight_genus2.off", "bands": b, "cycles": c} for b, c in ((1, 0), (11, 2), (22, 2))]
    assert thesis._reeb_steps(_runs(tmp_path, "figures/reeb_steps", {"reeb_steps": steps}))[0] == "illustration"
    skeletons = [{"clean.genus": 2, "reeb_graph.cycle_rank": 2}, {"clean.genus": 0, "reeb_graph.cycle_rank": 0}]
    assert thesis._genus_cycles(_runs(tmp_path / "b", "skeleton_gallery", {"skeletons": skeletons}))[0] == "differs"
    rows = [{"tx": 0.0, "ty": 0.0, "angle": 0.0, "mean_row_max": 1.0}, {"tx": 2.0, "ty": 0.0, "angle": 0.0,
                                                                         "mean_row_max": 0.3}]
    runs = _runs(tmp_path / "c", "registration/conditionals", {"fig2_4_conditionals": rows})
    assert thesis._conditionals(runs)[0] == "illustration"


def test_stability_is_reproduced_only_well_inside_the_limit_with_the_same_endpoints(tmp_path):
    def rows(distance, endpoints):
        return [{"input": "m", "morse.function": "mixture", "noise.sigma": s, "genus": 0, "skeleton_cycle_rank": 0,
                 "endpoints": 5 if s == 0 else endpoints, "endpoints_reference": 5,
                 "distance_mean_rel": 0.0 if s == 0 else distance} for s in (0.0, 0.001)]
    check = thesis._stability("robustness/noise", "noise_stability", 0.05, "clean", "mixture", {"noise.sigma": 0.0})
    for distance, endpoints, verdict in ((0.01, 5, "reproduced"), (0.01, 6, "partly"), (0.04, 5, "partly"),
                                         (0.2, 5, "differs")):
        runs = _runs(tmp_path / f"{distance}-{endpoints}", "robustness/noise", {"noise_stability": rows(distance, endpoints)})
        verdict_found, reason = check(runs)
        assert verdict_found == verdict, (distance, endpoints)
        assert f"changed in {int(endpoints != 5)} of 1 runs (the reference left out)" in reason


def test_retrieval_against_spherical_harmonics(tmp_path):
    def metrics(ours, sh):
        return [{"method": "rgpd", "average": "micro", "nn": ours, "first_tier": ours / 2},
                {"method": "sh", "average": "micro", "nn": sh, "first_tier": sh / 2}]
    runs = _runs(tmp_path, thesis.W, {"watertight_metrics": metrics(0.9, 0.8)})
    assert thesis._against_sh("rgpd")(runs)[0] == "reproduced"
    runs = _runs(tmp_path / "b", thesis.W, {"watertight_metrics": metrics(0.5, 0.8)})
    assert thesis._against_sh("rgpd")(runs)[0] == "differs"


def test_the_remaining_checks_move_with_their_tables(tmp_path):
    """Figs. 2.2, 2.3, 2.13-2.15, 3.13 / 4.10 and Tables 3.1 / 4.1: a table that contradicts the sentence moves the
    verdict (the audit of the twelfth session found these checks without such a test)."""
    def entropy(argmax, err):
        return [{"alpha": a, "argmax_p": argmax, "max": 1.0 + err, "max_exact": 1.0} for a in (0.5, 2.0)]
    e = "registration/entropy_bernoulli"
    assert thesis._entropy_max(_runs(tmp_path / "a", e, {"fig2_2_tsallis_entropy": entropy(0.5, 0.0)}))[0] == "reproduced"
    assert thesis._entropy_max(_runs(tmp_path / "b", e, {"fig2_2_tsallis_entropy": entropy(0.4, 0.0)}))[0] == "differs"
    assert thesis._entropy_max(_runs(tmp_path / "c", e, {"fig2_2_tsallis_entropy": entropy(0.5, 1e-3)}))[0] == "differs"

    def jt(at):
        return [{"alpha": 0.3, "min_on_diagonal": 0, "max": 0.9, "at_p": at[0], "at_q": at[1]}]
    assert thesis._jt_bernoulli(_runs(tmp_path / "d", e, {"fig2_3_jensen_tsallis": jt((0.0, 1.0))}))[0] == "reproduced"
    assert thesis._jt_bernoulli(_runs(tmp_path / "f", e, {"fig2_3_jensen_tsallis": jt((0.5, 1.0))}))[0] == "differs"

    def slices(peak, tre):
        curves = [{"peak_at": peak, "input": "a|b", "parameter": "tx", "alpha": 2.0}]
        return {"fig2_14_jt_uniform": curves, "fig2_15_jt_histogram": curves,
                "slices": [{"true_angle": 10.0, "true_tx": 10.0, "true_ty": 20.0, "tre_mean": tre}]}
    m = "registration/mri_volume_alpha"
    assert thesis._mri_slices(_runs(tmp_path / "g", m, slices(0.0, 0.05)))[0] == "reproduced"
    assert thesis._mri_slices(_runs(tmp_path / "h", m, slices(0.0, 5.0)))[0] == "partly"  # the slices do not register
    assert thesis._mri_slices(_runs(tmp_path / "i", m, slices(4.0, 5.0)))[0] == "differs"

    def metrics(ours, rival):
        return [{"method": "rgpd", "average": "micro", "map": ours}, {"method": "sh", "average": "micro", "map": rival}]
    pr = thesis._pr("rgpd", ("sh",))
    assert pr(_runs(tmp_path / "j", thesis.W, {"watertight_metrics": metrics(0.6, 0.4)}))[0] == "reproduced"
    assert pr(_runs(tmp_path / "k", thesis.W, {"watertight_metrics": metrics(0.3, 0.4)}))[0] == "differs"

    def seven(diagonal_hits):
        names = [f"c{i} 1" for i in range(3)]
        return [{"query": f"c{i} 0", **{n: f"{1.0 + j}" + (" *" if (j == i) == (i < diagonal_hits) else "")
                                        for j, n in enumerate(names)}} for i in range(3)]
    table = thesis._seven_by_seven("rgpd")
    assert table(_runs(tmp_path / "l", thesis.W, {"watertight_7x7_rgpd": seven(3)}))[0] == "reproduced"
    assert table(_runs(tmp_path / "m", thesis.W, {"watertight_7x7_rgpd": seven(2)}))[0] == "differs"
