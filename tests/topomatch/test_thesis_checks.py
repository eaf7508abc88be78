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
    assert jt(runs)[0] == "reproduced"
    runs = _runs(tmp_path / "e", "registration/landscapes", {"jt_u": _curves("T1|PD", [3.0, 1.0, 0.1], sharp=0.4),
                                                             "jt_h": _curves("T1|PD", [3.0, 1.0, 0.1], sharp=0.3)})
    assert jt(runs)[0] == "partly"  # not sharper than histogram weights


def test_endpoints_are_counted_against_the_protrusions(tmp_path):
    rows = [{"item": "odedstein_human_man.obj.gz[morse.function=mixture]", "prune.endpoints": 5},
            {"item": "odedstein_cat-low-resolution.obj.gz[morse.function=mixture]", "prune.endpoints": 6},
            {"item": "odedstein_cat-low-resolution.obj.gz[morse.function=fiedler]", "prune.endpoints": 3}]
    runs = _runs(tmp_path, "skeleton_gallery", {"skeletons": rows})
    assert thesis._one_per_protrusion("mixture", (("skeleton_gallery", "skeletons"),))(runs)[0] == "reproduced"
    verdict, reason = thesis._one_per_protrusion("fiedler", (("skeleton_gallery", "skeletons"),))(runs)
    assert verdict == "differs" and "cat 3 for 6" in reason


def test_stability_is_reproduced_only_well_inside_the_limit_with_the_same_endpoints(tmp_path):
    def rows(distance, endpoints):
        return [{"input": "m", "morse.function": "mixture", "genus": 0, "skeleton_cycle_rank": 0,
                 "endpoints": endpoints, "endpoints_reference": 5, "distance_mean_rel": distance}]
    check = thesis._stability("robustness/noise", "noise_stability", 0.05, "clean", "mixture")
    for distance, endpoints, verdict in ((0.01, 5, "reproduced"), (0.01, 6, "partly"), (0.04, 5, "partly"),
                                         (0.2, 5, "differs")):
        runs = _runs(tmp_path / f"{distance}-{endpoints}", "robustness/noise", {"noise_stability": rows(distance, endpoints)})
        assert check(runs)[0] == verdict, (distance, endpoints)


def test_retrieval_against_spherical_harmonics(tmp_path):
    def metrics(ours, sh):
        return [{"method": "rgpd", "average": "micro", "nn": ours, "first_tier": ours / 2},
                {"method": "sh", "average": "micro", "nn": sh, "first_tier": sh / 2}]
    runs = _runs(tmp_path, thesis.W, {"watertight_metrics": metrics(0.9, 0.8)})
    assert thesis._against_sh("rgpd")(runs)[0] == "reproduced"
    runs = _runs(tmp_path / "b", thesis.W, {"watertight_metrics": metrics(0.5, 0.8)})
    assert thesis._against_sh("rgpd")(runs)[0] == "differs"
