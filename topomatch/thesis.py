"""The thesis, figure by figure and table by table: which config reproduces it, what the thesis
claims, and a measured verdict read from the run's own tables (``topomatch thesis``, ``make thesis``).

:data:`CATALOGUE` lists every figure and table of the thesis (restated in THESIS.md) with its caption
and claim in one line, the bundled config that makes our version, the figures and tables to show,
and a check: a function of the run folder that returns ``(verdict, measured)``, the verdict being
``reproduced``, ``differs`` or ``shown`` (an illustration with no claim to measure), and
``measured`` the number behind it. :func:`reproduce` runs each config once (the configs that need
the external data root are skipped, with a note, when it is missing) and writes one page,
``thesis.html``, and ``thesis.json``.
"""

from __future__ import annotations

import html
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from topomatch.pipeline.errors import ConfigError, TopomatchError

Check = Callable[[Path], tuple[str, str]]


def table(run_dir: Path, name: str) -> list[dict[str, Any]]:
    """The rows of ``tables/<name>.json`` of a run folder."""
    return json.loads((run_dir / "tables" / f"{name}.json").read_text())


def _verdict(ok: bool) -> str:
    return "reproduced" if ok else "differs"


# --------------------------------------------------------------------------- checks, one per claim


def _entropy_max(run_dir: Path) -> tuple[str, str]:
    rows = table(run_dir, "fig2_2_tsallis_entropy")
    err = max(abs(r["max"] - r["max_exact"]) for r in rows)
    ok = all(r["argmax_p"] == 0.5 for r in rows) and err < 1e-9
    return _verdict(ok), f"maximum at p = 0.5 for all {len(rows)} α; largest error against the closed form {err:.1g}"


def _jt_bernoulli(run_dir: Path) -> tuple[str, str]:
    rows = table(run_dir, "fig2_3_jensen_tsallis")
    ok = all(r["min_on_diagonal"] == 0 and {r["at_p"], r["at_q"]} == {0.0, 1.0} for r in rows)
    return _verdict(ok), "; ".join(f"α = {r['alpha']}: 0 on p = q, maximum {r['max']:.3f} at (p, q) = "
                                   f"({r['at_p']:g}, {r['at_q']:g})" for r in rows)


def _conditionals(run_dir: Path) -> tuple[str, str]:
    rows = table(run_dir, "fig2_4_conditionals")
    aligned = [r for r in rows if (r["tx"], r["ty"], r["angle"]) == (0.0, 0.0, 0.0)]
    moved = [r for r in rows if (r["tx"], r["ty"], r["angle"]) != (0.0, 0.0, 0.0)]
    ok = min(r["mean_row_max"] for r in aligned) > max(r["mean_row_max"] for r in moved)
    return _verdict(ok), (f"mean row maximum of the conditionals {min(r['mean_row_max'] for r in aligned):.2f} "
                          f"aligned vs at most {max(r['mean_row_max'] for r in moved):.2f} misaligned")


def _recovery(run_dir: Path) -> tuple[str, str]:
    rows = [r for r in table(run_dir, "recovery_summary") if r["pairs"] == "all"]
    by = {r["method"]: r["median_tre"] for r in rows}
    best = min(by, key=by.get)
    jt = next(m for m in by if "jt(" in m)
    text = ", ".join(f"{m.split('/')[-1].split('(')[0]} {v:.3f}" for m, v in sorted(by.items(), key=lambda kv: kv[1]))
    return _verdict(best == jt), f"median TRE (px): {text}; lowest success rate of a method " \
                                 f"{min(r['success_rate'] for r in rows):.0%}"


def _landscape(name: str) -> Check:
    def check(run_dir: Path) -> tuple[str, str]:
        rows = table(run_dir, name)
        peaked = [r for r in rows if r["peak_at"] == 0.0]
        off = [f"{r['measure']}, {r['parameter']}, α = {r['alpha']}: peak at {r['peak_at']:g}"
               for r in rows if r["peak_at"] != 0.0]
        return _verdict(not off), f"peak at the alignment in {len(peaked)} of {len(rows)} curves" + \
            (f" (not: {'; '.join(off[:3])}{' ...' if len(off) > 3 else ''})" if off else "")
    return check


def _mri_slices(run_dir: Path) -> tuple[str, str]:
    verdict, measured = _landscape("fig2_13_2_15_alpha")(run_dir)
    r = table(run_dir, "slices")[0]
    return verdict, f"{measured}; registration of the two slices: tx {r['tx']:.3f}, ty {r['ty']:.3f} px, angle {r['angle']:.3f}°"


def _level_sets(run_dir: Path) -> tuple[str, str]:
    rows = table(run_dir, "level_sets")
    return "shown", f"{len(rows)} panels, {rows[0].get('level_sets.levels', 22)} bands each (an illustration)"


def _reeb_steps(run_dir: Path) -> tuple[str, str]:
    rows = [r for r in table(run_dir, "reeb_steps") if r["item"].startswith("eight_genus2")]
    last = rows[-1]
    cycles = " -> ".join(str(r["cycles"]) for r in rows)
    return _verdict(last["cycles"] == 2), f"double torus: cycles after {', '.join(str(r['bands']) for r in rows)} " \
                                          f"bands: {cycles} (genus 2)"


def _endpoint_paths(run_dir: Path) -> tuple[str, str]:
    rows = table(run_dir, "endpoint_paths")
    sums: dict[str, float] = {}
    for r in rows:
        sums[r["item"]] = sums.get(r["item"], 0.0) + r["dc"]
    ok = all(abs(s - 1) < 1e-9 for s in sums.values())
    return _verdict(ok), f"{len(rows)} endpoints on {len(sums)} shapes; Σ dc_i = 1 on every shape " \
                         f"(largest deviation {max(abs(s - 1) for s in sums.values()):.1g})"


def _genus_cycles(run_dir: Path) -> tuple[str, str]:
    rows = table(run_dir, "skeletons")
    bad = [r for r in rows if r.get("clean.genus") is not None and r.get("reeb_graph.cycle_rank") is not None
           and r["clean.genus"] != r["reeb_graph.cycle_rank"]]
    closed = [r for r in rows if r.get("clean.genus") is not None]
    return _verdict(not bad), f"Reeb-graph cycles = genus on {len(closed) - len(bad)} of {len(closed)} skeletons " \
                              f"(double torus: 2)"


def _stability(name: str, limit: float, what: str, function: str | None = None) -> Check:
    def check(run_dir: Path) -> tuple[str, str]:
        rows = [r for r in table(run_dir, name) if function is None or r.get("morse.function") == function]
        worst = max(rows, key=lambda r: r["distance_mean_rel"])
        cycles_kept = sum(r["skeleton_cycle_rank"] == r["genus"] for r in rows if r["genus"] is not None)
        return _verdict(worst["distance_mean_rel"] <= limit), (
            f"largest mean distance to the {what} skeleton {worst['distance_mean_rel']:.3g} × bbox diagonal "
            f"({worst['input']}, claim held if ≤ {limit:g}); cycles = genus in {cycles_kept} of "
            f"{sum(r['genus'] is not None for r in rows)}")
    return check


def _seven_by_seven(method: str) -> Check:
    def check(run_dir: Path) -> tuple[str, str]:
        rows = table(run_dir, f"watertight_7x7_{method}")
        hits = sum(str(list(r.values())[1 + i]).endswith("*") for i, r in enumerate(rows))
        return _verdict(hits == len(rows)), f"{method.upper()}: smallest value on the diagonal in {hits} of {len(rows)} rows"
    return check


def _metrics(run_dir: Path) -> dict[str, dict[str, float]]:
    return {r["method"]: r for r in table(run_dir, "watertight_metrics") if r["average"] == "micro"}


def _pr(method: str, rivals: tuple[str, ...]) -> Check:
    def check(run_dir: Path) -> tuple[str, str]:
        m = _metrics(run_dir)
        ours = m[method]["map"]
        others = {k: m[k]["map"] for k in rivals if k in m}
        best_rival = max(others, key=others.get)
        return _verdict(ours > others[best_rival]), (
            f"mAP {method.upper()} {ours:.3f} vs " + ", ".join(f"{k.upper()} {v:.3f}" for k, v in others.items())
            + f" (SHREC'07 Watertight; medial surfaces not available; topomatch fusion {m.get('topomatch', {}).get('map', math.nan):.3f})")
    return check


def _top(method: str, k: str) -> Check:
    def check(run_dir: Path) -> tuple[str, str]:
        m = _metrics(run_dir)
        return "shown", f"{method.upper()} nearest neighbour {m[method]['nn']:.3f}, first tier {m[method]['first_tier']:.3f} " \
                        f"(SHREC'07 Watertight in place of {k})"
    return check


def _shown(text: str) -> Check:
    return lambda run_dir: ("shown", text)


# --------------------------------------------------------------------------- the catalogue


@dataclass(frozen=True)
class ThesisItem:
    """One figure or table of the thesis and how we reproduce it."""

    id: str
    caption: str
    claim: str
    config: str
    show: tuple[str, ...]
    check: Check
    note: str = ""


W = "retrieval/watertight"
CATALOGUE: tuple[ThesisItem, ...] = (
    ThesisItem("Fig. 2.2", "Tsallis entropy of a Bernoulli (p, 1-p) for several α",
               "symmetric, maximal at p = 1/2 for every α", "registration/entropy_bernoulli",
               ("figures/fig2_2_tsallis_entropy.png",), _entropy_max),
    ThesisItem("Fig. 2.3", "Jensen-Tsallis divergence between two Bernoulli distributions, α = 0.3 and 1.2",
               "zero when the distributions agree, largest for opposite one-hot ones", "registration/entropy_bernoulli",
               ("figures/fig2_3_jensen_tsallis.png",), _jt_bernoulli),
    ThesisItem("Figs. 2.4-2.5", "conditional distributions p_i for θ = (0,0,0), (2,0,0), (0,0,5), (5,0,-15)",
               "crisp when aligned, dispersed when not", "registration/conditionals",
               ("figures/fig2_4_conditionals_*.png",), _conditionals),
    ThesisItem("Figs. 2.6-2.8", "recovered θ and errors on three reference images for JT, JR, MI, Tsallis MI",
               "JT + SPSA is the most accurate", "registration/recovery",
               ("figures/fig2_6_to_2_8_*.png", "tables/recovery_summary.csv"), _recovery),
    ThesisItem("Figs. 2.9-2.10", "Jensen-Tsallis as each parameter varies; histogram vs uniform weights, several α",
               "peaked at the alignment", "registration/landscapes",
               ("figures/fig2_9_2_10_jensen_tsallis.png",), _landscape("fig2_9_2_10_jensen_tsallis")),
    ThesisItem("Figs. 2.11-2.12", "Jensen-Rényi as each parameter varies; both weightings, several α",
               "peaked at the alignment", "registration/landscapes",
               ("figures/fig2_11_2_12_jensen_renyi.png",), _landscape("fig2_11_2_12_jensen_renyi")),
    ThesisItem("Figs. 2.13-2.15", "two slices of an MRI volume: JT vs each parameter for several α",
               "peaked at the alignment for every α; the slices register", "registration/mri_volume_alpha",
               ("figures/fig2_13_2_15_alpha.png", "figures/slices_registered.png"), _mri_slices,
               note="the thesis's 27-slice 128×128 volume is not available: slices 30/31 of ITK's T1 volume"),
    ThesisItem("Fig. 3.1", "level sets of the Euclidean and affine distances",
               "the affine distance's level sets follow the shape's elongation", "figures/level_sets",
               ("figures/level_sets.png",), _level_sets),
    ThesisItem("Fig. 3.2", "Reeb graph extraction at several steps of Algorithm 1",
               "nodes are band components; the double torus's two loops appear", "figures/reeb_steps",
               ("figures/reeb_steps.png", "tables/reeb_steps.csv"), _reeb_steps),
    ThesisItem("Fig. 3.3", "skeleton of a double torus", "two independent cycles (genus 2)", "skeleton_gallery",
               ("figures/skeletons.png", "tables/skeletons.csv"), _genus_cycles),
    ThesisItem("Figs. 3.4-3.6", "endpoints; shortest paths between endpoints and from the centroid",
               "the endpoint features a, dv, dc come from these paths", "figures/endpoint_paths",
               ("figures/endpoint_paths.png", "tables/endpoint_paths.csv"), _endpoint_paths),
    ThesisItem("Fig. 3.7", "skeletons from the affine and the mixture distance",
               "the mixture distance gives the more faithful skeleton", "skeleton_gallery", ("figures/skeletons.png",),
               _shown("affine, mixture and Fiedler skeletons side by side (a visual comparison)")),
    ThesisItem("Fig. 3.8", "skeletons of other models", "one branch per protrusion", "skeleton_gallery",
               ("figures/skeletons.png",), _shown("skeletons of the bundled models")),
    ThesisItem("Fig. 3.9", "skeletons under vertex noise", "skeletons stay close to the clean ones",
               "robustness/noise", ("figures/noise_stability.png", "figures/noise_skeletons_mixture.png"),
               _stability("noise_stability", 0.05, "clean", "mixture")),
    ThesisItem("Fig. 3.10", "decimation 25,600 -> 6,400 -> 1,600 triangles", "skeletons stay close",
               "robustness/decimation", ("figures/decimation_stability.png", "figures/decimation_skeletons_mixture.png"),
               _stability("decimation_stability", 0.05, "25,600-triangle")),
    ThesisItem("Fig. 3.11", "rotation by 90° and scaling by 2", "identical skeletons", "robustness/invariance",
               ("figures/invariance.png", "figures/invariance_skeletons.png"), _stability("invariance", 1e-6, "original")),
    ThesisItem("Table 3.1", "7×7 dissimilarity matrix (RGPD)", "the smallest value of each row on the diagonal", W,
               ("tables/watertight_7x7_rgpd.csv",), _seven_by_seven("rgpd")),
    ThesisItem("Table 3.2", "top-10 retrieved objects (McGill), RGPD vs spherical harmonics",
               "RGPD retrieves the query's class", W, ("figures/watertight_top10_rgpd.png",), _top("rgpd", "McGill")),
    ThesisItem("Table 3.3", "top-5 retrieved objects (Princeton), RGPD vs spherical harmonics",
               "RGPD retrieves the query's class", W, ("figures/watertight_top10_rgpd.png",), _top("rgpd", "Princeton")),
    ThesisItem("Fig. 3.13", "precision-recall: RGPD vs spherical harmonics vs medial surfaces",
               "RGPD clearly best", W, ("figures/watertight_pr.png", "tables/watertight_metrics.csv"),
               _pr("rgpd", ("sh", "d2", "shapedna"))),
    ThesisItem("Fig. 3.12", "sample models of the McGill articulated benchmark", "ten articulated classes",
               W, ("figures/watertight_top10_rgpd.png",),
               _shown("SHREC'07 Watertight models in place of McGill's (not available; 7 classes shared), shown in "
                      "the top-10 grids")),
    ThesisItem("Fig. 4.3", "sparsity patterns of Q and K (tooth)", "Q and K share the mesh's edge pattern",
               "figures/spectral_tooth", ("figures/tooth*.png",), _shown("the tooth from the data root")),
    ThesisItem("Fig. 4.4", "tooth coloured by φ1, φ2 and the level sets of φ2",
               "φ1 constant, φ2 follows the elongation", "figures/spectral_tooth", ("figures/tooth*.png",),
               _shown("φ1..φ3 and the level sets of φ2 on the tooth")),
    ThesisItem("Figs. 4.5-4.6", "spectral Reeb graphs of the horse and octopus with endpoints",
               "one endpoint per limb", "skeleton_gallery", ("figures/skeletons.png", "figures/spectral*.png"),
               _shown("Fiedler skeletons of the bundled models (horse and octopus: data root, configs/robustness)")),
    ThesisItem("Figs. 4.7-4.8", "endpoints of a spectral Reeb graph; paths between endpoints and from the centroid",
               "the endpoint features a, dv, dc come from these paths (as in chapter 3)", "figures/endpoint_paths_fiedler",
               ("figures/endpoint_paths.png", "tables/endpoint_paths.csv"), _endpoint_paths),
    ThesisItem("Fig. 4.9", "spectral Reeb graph under noise", "skeletons stay close", "robustness/noise",
               ("figures/noise_stability.png", "figures/noise_skeletons_fiedler.png"),
               _stability("noise_stability", 0.05, "clean", "fiedler")),
    ThesisItem("Table 4.1", "7×7 dissimilarity matrix (SRG)", "the smallest value of each row on the diagonal", W,
               ("tables/watertight_7x7_srg.csv",), _seven_by_seven("srg")),
    ThesisItem("Table 4.2", "top-10 retrieval, SRG vs RGPD vs SH", "SRG retrieves the query's class", W,
               ("figures/watertight_top10_srg.png",), _top("srg", "McGill")),
    ThesisItem("Fig. 4.10", "precision-recall, McGill: SRG vs RGPD vs SH vs medial surfaces", "SRG best", W,
               ("figures/watertight_pr.png",), _pr("srg", ("rgpd", "sh", "d2", "shapedna"))),
    ThesisItem("Table 4.3", "top-5 retrieval on the Princeton Shape Benchmark", "SRG retrieves the query's class", W,
               ("figures/watertight_top10_srg.png",), _top("srg", "Princeton")),
)


# --------------------------------------------------------------------------- running and the page


@dataclass
class Outcome:
    """What happened to one thesis item: the run folder (or why there is none), verdict and number."""

    item: ThesisItem
    run_dir: Path | None = None
    verdict: str = "not run"
    measured: str = ""
    files: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.item.id, "caption": self.item.caption, "claim": self.item.claim,
                "config": self.item.config, "verdict": self.verdict, "measured": self.measured,
                "run_dir": str(self.run_dir) if self.run_dir else None, "files": self.files, "note": self.item.note}


def reproduce(out: str | Path = "thesis", *, data_root: str | Path | None = None, only: list[str] | None = None,
              progress: Callable[[str], None] | None = None) -> list[Outcome]:
    """Run the configs of the thesis's figures and tables (each once) into ``out`` and write
    ``out/thesis.html`` and ``out/thesis.json``. ``only``: item ids or config names to keep
    (``["Fig. 3.1", "robustness/noise"]``; an id may be given without its prefix: ``3.1``)."""
    from topomatch.experiments import CONFIGS_DIR, load_config
    from topomatch.pipeline.runner import run_experiment

    out = Path(out)
    items = [i for i in CATALOGUE if not only or any(_matches(i, s) for s in only)]
    unknown = [s for s in only or [] if not any(_matches(i, s) for i in CATALOGUE)]
    if unknown:  # every selector must name something, not only one of them
        raise ConfigError(f"no thesis figure or table matches {', '.join(unknown)}; ids look like "
                             f"'Fig. 3.9', '3.9' or 'Table 3.1', configs like 'robustness/noise'")
    runs: dict[str, tuple[Path | None, str]] = {}
    for config in dict.fromkeys(i.config for i in items):
        if progress:
            progress(f"thesis: running {config}")
        t = time.perf_counter()
        try:
            experiment = load_config(CONFIGS_DIR / f"{config}.yaml", data_root_dir=data_root)
            outcome = run_experiment(experiment, out_root=out / "runs", progress=False)
            failed = f"{len(outcome.failed)} items failed: {outcome.failed[0].error}" if outcome.failed else ""
            runs[config] = (outcome.run_dir, failed)
        except TopomatchError as exc:  # a missing data root or file: noted, the others still run
            runs[config] = (None, str(exc))
        if progress:
            progress(f"thesis: {config} done in {time.perf_counter() - t:.1f} s")
    outcomes = []
    for item in items:
        run_dir, problem = runs[item.config]
        o = Outcome(item, run_dir)
        if run_dir is None:
            o.verdict, o.measured = "not run", problem
        else:
            for pattern in item.show:
                o.files += sorted(p.relative_to(run_dir).as_posix() for p in run_dir.glob(pattern))
            try:
                o.verdict, o.measured = item.check(run_dir)
            except (OSError, KeyError, IndexError, ValueError, StopIteration) as exc:
                o.verdict, o.measured = "not measured", f"{type(exc).__name__}: {exc}"
            if problem:
                o.measured += f" ({problem})"
        outcomes.append(o)
    write_page(out, outcomes)
    return outcomes


def _matches(item: ThesisItem, selector: str) -> bool:
    """Whether ``selector`` names ``item``: its id ('Fig. 3.9', 'Table 3.1'), its config, or a bare figure
    number ('3.9', also '3.5' for 'Figs. 3.4-3.6'; tables need their 'Table' prefix)."""
    s = selector.strip().lower()
    if s in (item.id.lower(), item.config.lower()):
        return True
    if not (s[:1].isdigit() and item.id.startswith("Fig")):
        return False
    numbers = item.id.split(" ", 1)[-1]
    lo, _, hi = numbers.partition("-")
    try:
        key = tuple(int(x) for x in s.split("."))
        return tuple(int(x) for x in lo.split(".")) <= key <= tuple(int(x) for x in (hi or lo).split("."))
    except ValueError:
        return False


def write_page(out: Path, outcomes: list[Outcome]) -> None:
    """``thesis.html``: one row per figure or table (caption, claim, our figure or table, verdict with the
    number, the config), and ``thesis.json`` with the same."""
    from topomatch.pipeline.files import atomic_write_text
    from topomatch.pipeline.reports import html_table

    esc = html.escape
    counts: dict[str, int] = {}
    for o in outcomes:
        counts[o.verdict] = counts.get(o.verdict, 0) + 1
    colour = {"reproduced": "#070", "differs": "#b00", "shown": "#555", "not run": "#a60", "not measured": "#a60"}
    parts = ["<!doctype html><html lang='en'><head><meta charset='utf-8'><title>The thesis, reproduced</title>",
             "<style>body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1400px;padding:0 1em;color:#222}"
             "section{border-top:1px solid #ddd;padding:.6em 0} .v{font-weight:600} img{max-width:48%;margin:.3em;"
             "border:1px solid #eee;vertical-align:top} .scroll{overflow-x:auto} table{border-collapse:collapse;"
             "font-size:12px} td,th{border:1px solid #ccc;padding:2px 6px;white-space:nowrap} .meta{color:#666}"
             "</style></head><body>",
             "<h1>W. Mohamed's thesis, figure by figure</h1>",
             "<p>Each thesis figure and table: its caption and claim, our figure or table, the measured verdict "
             "(<b>reproduced</b>: the claim holds on our data, with the number; <b>differs</b>: it does not; "
             "<b>shown</b>: an illustration with no claim to measure; <b>not run</b>: data missing) and the config "
             "that made it (<code>topomatch run CONFIG</code> makes it alone).</p>",
             "<p>" + " · ".join(f"<span style='color:{colour.get(k, '#222')}'>{v} {esc(k)}</span>"
                                for k, v in sorted(counts.items())) + "</p>",
             "<table><tr><th>thesis</th><th>claim</th><th>verdict</th><th>config</th></tr>" + "".join(
                 f"<tr><td><a href='#{esc(_anchor(o.item.id))}'>{esc(o.item.id)}</a></td><td>{esc(o.item.claim)}</td>"
                 f"<td style='color:{colour.get(o.verdict, '#222')}'>{esc(o.verdict)}</td><td>{esc(o.item.config)}</td></tr>"
                 for o in outcomes) + "</table>"]
    for o in outcomes:
        rel = o.run_dir.relative_to(out).as_posix() if o.run_dir else None
        parts.append(f"<section id='{esc(_anchor(o.item.id))}'><h2>{esc(o.item.id)}: {esc(o.item.caption)}</h2>")
        parts.append(f"<p><b>Thesis claim:</b> {esc(o.item.claim)}.<br><b>Verdict:</b> <span class='v' "
                     f"style='color:{colour.get(o.verdict, '#222')}'>{esc(o.verdict)}</span> — {esc(o.measured)}</p>")
        if o.item.note:
            parts.append(f"<p class='meta'>{esc(o.item.note)}</p>")
        for f in o.files:
            if f.endswith((".png", ".svg")):
                parts.append(f"<img src='{esc(rel)}/{esc(f)}' alt='{esc(f)}'>")
            elif f.endswith(".csv"):
                rows = json.loads((o.run_dir / f.replace(".csv", ".json")).read_text())
                parts.append(f"<p>Table <a href='{esc(rel)}/{esc(f)}'>{esc(Path(f).name)}</a></p>" + html_table(rows, limit=30))
        config = f"configs/{o.item.config}.yaml"
        run = f" · <a href='{esc(rel)}/index.html'>run page</a>" if rel else ""
        parts.append(f"<p class='meta'>Config: <code>{esc(config)}</code>{run}</p></section>")
    parts.append("</body></html>")
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "thesis.html", "\n".join(parts))
    atomic_write_text(out / "thesis.json", json.dumps([o.to_dict() for o in outcomes], indent=1))


def _anchor(ident: str) -> str:
    return ident.lower().replace(" ", "").replace(".", "-")
