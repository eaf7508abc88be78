"""Reports of the registration experiments (thesis ch. 2): the figures 2.2-2.15 (analytic curves, conditional
distributions, recovered parameters, landscapes), overlays of registered pairs, and tables of the registrations and of
their accuracy per method."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, ReportOutput, report
from topomatch.stages.registration.divergence import conditionals, jensen_tsallis_histogram, tsallis_entropy
from topomatch.stages.registration.evaluate import EvaluateResult
from topomatch.stages.registration.histogram import Binning, JointHistogram
from topomatch.stages.registration.interpolation import resample
from topomatch.stages.registration.landscape import LandscapeResult
from topomatch.stages.registration.register import RegisterResult, describe
from topomatch.stages.registration.transform import RigidTransform

_NAME = dict(pattern=r"^[A-Za-z0-9_.-]+$", description="file name of the figure or table")


def _stem(path: str) -> str:
    name = Path(str(path).split("|")[0]).name
    for suffix in (".nii.gz", ".png", ".tif", ".tiff", ".nii", ".mha", ".mhd", ".dcm"):
        name = name.removesuffix(suffix)
    return name


def _label(r) -> str:
    """Short input label of an item: 'fixed|moving' stems for pairs, the stem for images."""
    return "|".join(_stem(p) for p in str(r.input_label or r.input_path).split("|"))


def _of_type(r, cls: type) -> list:
    """Every result of class ``cls`` in an item, in chain order."""
    return [res for res in r.results.values() if isinstance(res, cls)]


# --------------------------------------------------------------------------- Figs. 2.2-2.3


class BernoulliEntropyParams(Params):
    name: str = Field("fig2_2_tsallis_entropy", **_NAME)
    alphas: list[float] = Field(default_factory=lambda: [0.3, 0.5, 1.0, 1.5, 2.0, 3.0], min_length=1,
                                description="entropy orders (1 is Shannon)")


@report("bernoulli_entropy", params=BernoulliEntropyParams)
def bernoulli_entropy_report(experiment, results, params: BernoulliEntropyParams) -> ReportOutput:
    """Fig. 2.2: Tsallis entropy of a Bernoulli distribution (p, 1 - p) for several alpha."""
    import matplotlib.pyplot as plt

    p = np.linspace(0, 1, 401)
    P = np.column_stack([p, 1 - p])
    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    rows = []
    for alpha in params.alphas:
        h = tsallis_entropy(P, alpha, axis=1)
        ax.plot(p, h, label=f"alpha = {alpha:g}" + (" (Shannon)" if alpha == 1 else ""))
        rows.append({"alpha": alpha, "max": float(h.max()), "argmax_p": float(p[np.argmax(h)]),
                     "max_exact": float((2 ** (1 - alpha) - 1) / (1 - alpha)) if alpha != 1 else float(np.log(2))})
    ax.set(xlabel="p", ylabel="H_alpha(p, 1 - p)")
    ax.set_title("Tsallis entropy of a Bernoulli distribution (thesis Fig. 2.2)", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return ReportOutput(tables={params.name: rows}, figures={params.name: fig})


class BernoulliJTParams(Params):
    name: str = Field("fig2_3_jensen_tsallis", **_NAME)
    alphas: list[float] = Field(default_factory=lambda: [0.3, 1.2], min_length=1, description="entropy orders")
    points: int = Field(101, ge=5, le=1001, description="grid points per axis")


@report("bernoulli_jt", params=BernoulliJTParams)
def bernoulli_jt_report(experiment, results, params: BernoulliJTParams) -> ReportOutput:
    """Fig. 2.3: Jensen-Tsallis divergence of two Bernoulli distributions, equal weights (surface and contours)."""
    import matplotlib.pyplot as plt

    g = np.linspace(0, 1, params.points)
    p, q = np.meshgrid(g, g, indexing="ij")
    P1, P2 = (np.stack([x, 1 - x], axis=-1) for x in (p, q))
    n = len(params.alphas)
    fig = plt.figure(figsize=(4.6 * n, 8))
    rows = []
    for k, alpha in enumerate(params.alphas):
        jt = tsallis_entropy(0.5 * (P1 + P2), alpha) - 0.5 * (tsallis_entropy(P1, alpha) + tsallis_entropy(P2, alpha))
        ax = fig.add_subplot(2, n, k + 1, projection="3d")
        ax.plot_surface(p, q, jt, cmap="viridis", linewidth=0, antialiased=True)
        ax.set(xlabel="p", ylabel="q")
        ax.set_title(f"JT, alpha = {alpha:g}", fontsize=9)
        ax2 = fig.add_subplot(2, n, n + k + 1)
        cs = ax2.contour(p, q, jt, levels=12, cmap="viridis")
        ax2.clabel(cs, fontsize=6)
        fig.colorbar(cs, ax=ax2, shrink=0.8, label=f"JT (alpha = {alpha:g})")
        ax2.set(xlabel="p", ylabel="q", aspect="equal")
        rows.append({"alpha": alpha, "max": float(jt.max()), "at_p": float(p.flat[np.argmax(jt)]),
                     "at_q": float(q.flat[np.argmax(jt)]), "min_on_diagonal": float(np.abs(np.diag(jt)).max())})
    fig.suptitle("Jensen-Tsallis divergence of (p, 1-p) and (q, 1-q), equal weights (thesis Fig. 2.3): "
                 "0 on p = q, largest for opposite one-hot distributions", fontsize=9)
    fig.tight_layout()
    return ReportOutput(tables={params.name: rows}, figures={params.name: fig})


# --------------------------------------------------------------------------- Figs. 2.4-2.5


class ConditionalParams(Params):
    name: str = Field("fig2_4_conditionals", **_NAME)
    transforms: list[list[float]] = Field(
        default_factory=lambda: [[0, 0, 0], [0, 2, 0], [5, 0, 0], [-15, 5, 0]], min_length=1,
        description="parameters of the moved copies, SimpleITK's order, angles in degrees (2D: angle, tx, ty)")
    bins: int = Field(32, ge=2, le=256, description="histogram bins")
    alpha: float = Field(2.0, gt=0, description="order of the JT value shown")
    rows_shown: int = Field(6, ge=1, description="conditional distributions drawn as curves")


@report("conditional_distributions", params=ConditionalParams)
def conditional_distributions_report(experiment, results, params: ConditionalParams) -> ReportOutput:
    """Figs. 2.4-2.5: conditional distributions p_i of an image against itself moved by a few transforms."""
    import matplotlib.pyplot as plt

    figures, table = {}, []
    for r in results:
        image = r.final("image") if r.final("image") is not None else r.final("fixed")
        if image is None:
            continue
        binning = Binning.of(image.data, params.bins)
        jh = JointHistogram(image, image, binning, binning, center=image.center, mode="linear")
        n = len(params.transforms)
        fig, axes = plt.subplots(2, n, figsize=(3.3 * n, 6.2), squeeze=False)
        for k, theta in enumerate(params.transforms):
            t = RigidTransform.from_degrees(theta, image.center)
            h, _ = jh(np.asarray(t.parameters))
            P, w = conditionals(h)
            jt = jensen_tsallis_histogram(h, params.alpha)
            full = np.zeros_like(h)
            full[h.sum(axis=1) > 0] = P  # the rows the conditionals are defined on
            ax = axes[0][k]
            ax.imshow(full, cmap="magma", aspect="auto", origin="lower", vmin=0, vmax=1)
            ax.set_title(f"theta = {tuple(float(t) for t in theta)}\nJT(alpha={params.alpha:g}) = {jt:.3f}", fontsize=8)
            ax.set(xlabel="target bin j", ylabel="reference bin i")
            ax = axes[1][k]
            top = np.argsort(w)[::-1][: params.rows_shown]
            for i in sorted(top):
                ax.plot(P[i], lw=1)
            ax.set(xlabel="target bin j", ylabel="p_ij", ylim=(0, 1.02))
            ax.set_title(f"{len(top)} most frequent rows", fontsize=8)
            table.append({"input": _label(r), **dict(zip(t.names, theta)), "jt": jt,
                          "mean_row_max": float((w * P.max(axis=1)).sum())})
        fig.suptitle(f"{_label(r)}: conditional distributions of the reference bins (rows of the joint histogram); "
                     f"crisp when aligned, dispersed when not (thesis Figs. 2.4-2.5)", fontsize=9)
        fig.tight_layout()
        figures[f"{params.name}_{_stem(r.input_path)}"] = fig
    return ReportOutput(tables={params.name: table}, figures=figures)


# --------------------------------------------------------------------------- Figs. 2.6-2.8


class BarsParams(Params):
    name: str = Field("fig2_6_recovered", **_NAME)


@report("registration_bars", params=BarsParams)
def registration_bars_report(experiment, results, params: BarsParams) -> ReportOutput:
    """Figs. 2.6-2.8: recovered parameters and absolute errors per measure, per true misalignment and image; with
    several seeds (a ``register.seed`` sweep) the bars are the median over the seeds, the whiskers their range."""
    import matplotlib.pyplot as plt

    data: dict[str, dict[tuple, dict[str, list[tuple]]]] = {}
    for r in (r for r in results if r.ok):
        for ev in _of_type(r, EvaluateResult):
            t, est = tuple(ev.truth.values()), tuple(ev.truth[n] + ev.errors[n] for n in ev.truth)
            data.setdefault(_label(r), {}).setdefault(tuple(round(v, 6) for v in t), {}).setdefault(
                ev.method, []).append((tuple(ev.truth), t, est, ev, r.sweep.get("register.seed")))
    figures, table = {}, []
    for image, cases in data.items():
        cols = len(cases)
        fig, axes = plt.subplots(2, cols, figsize=(4.4 * cols, 6.4), squeeze=False)
        for c, by_method in enumerate(cases.values()):
            width = 0.8 / len(by_method)  # each case has a method
            names, truth = next(iter(by_method.values()))[0][:2]
            x = np.arange(len(names))
            for m, (method, runs) in enumerate(by_method.items()):
                est = np.array([run[2] for run in runs])                    # (seeds, parameters)
                errs = np.abs(est - np.array(truth))
                label = method.split("/")[-1].split("(")[0].upper()
                at = x + (m - (len(by_method) - 1) / 2) * width
                for row, values in ((0, est), (1, errs)):
                    mid = np.median(values, axis=0)
                    spread = np.array([mid - values.min(axis=0), values.max(axis=0) - mid]) if len(runs) > 1 else None
                    axes[row][c].bar(at, mid, width, yerr=spread, capsize=2, label=label)
                for (_, t, e, ev, seed), err in zip(runs, errs):
                    table.append({"input": image, **{f"true_{n}": v for n, v in zip(names, t)}, "method": method,
                                  **({"seed": seed} if seed is not None else {}), **dict(zip(names, e)),
                                  **{f"err_{n}": float(v) for n, v in zip(names, err)},
                                  "tre_mean": ev.tre_mean, "success": ev.success})
            for j in range(len(names)):
                axes[0][c].hlines(truth[j], j - 0.45, j + 0.45, colors="k", linestyles="--", lw=1)
            axes[0][c].set_xticks(x, names)
            axes[1][c].set_xticks(x, [f"|{n} err|" for n in names])
            axes[0][c].set_title(f"true ({', '.join(f'{n} {v:g}' for n, v in zip(names, truth))}) (dashed)", fontsize=8)
            axes[1][c].set(yscale="log", ylim=(1e-4, 100))
            axes[1][c].axhline(1.0, color="0.5", lw=0.6)
        axes[0][0].set_ylabel("recovered (deg, px)")
        axes[1][0].set_ylabel("absolute error (log)")
        axes[0][-1].legend(fontsize=7)
        seeds = max(len(runs) for by_method in cases.values() for runs in by_method.values())
        fig.suptitle(f"{image}: recovered parameters and errors per measure" + (
            f", median and range over {seeds} seeds" if seeds > 1 else "") + " (thesis Figs. 2.6-2.8)", fontsize=9)
        fig.tight_layout()
        figures[f"{params.name}_{image.replace('|', '_')}"] = fig
    return ReportOutput(tables={params.name: table}, figures=figures)


# --------------------------------------------------------------------------- Figs. 2.9-2.15


class LandscapePlotParams(Params):
    name: str = Field("landscapes", **_NAME)
    normalize: Literal["max", "none"] = Field("max", description="divide each curve by its maximum, or not")
    where: dict[str, float | int | str | bool] = Field(default_factory=dict,
                                                       description="only items with these sweep values")
    title: str = ""


@report("landscape_plot", params=LandscapePlotParams)
def landscape_plot_report(experiment, results, params: LandscapePlotParams) -> ReportOutput:
    """Figs. 2.9-2.15: the measure against each parameter, one line per alpha, one row per item."""
    import matplotlib.pyplot as plt

    rows = [(r, res) for r in results if all(r.sweep.get(k) == v for k, v in params.where.items())
            for res in _of_type(r, LandscapeResult)]
    if not rows:
        return ReportOutput(notes=["no landscape results"])
    width = max(len(res.values) for _, res in rows)
    fig, axes = plt.subplots(len(rows), width, figsize=(4.3 * width, 2.9 * len(rows)), squeeze=False)
    table = []
    for k, (r, res) in enumerate(rows):
        for j, name in enumerate(res.values):
            ax = axes[k][j]
            for alpha, v in zip(res.alphas, res.values[name]):
                scale = np.nanmax(v) if params.normalize == "max" and np.nanmax(v) > 0 else 1.0
                ax.plot(res.offsets[name] + res.center[j], v / scale, label=f"alpha = {alpha:g}")
                sharp = float(np.nanmean(v) / np.nanmax(v)) if np.nanmax(v) > 0 else float("nan")
                table.append({"input": _label(r), "measure": res.label, "parameter": name, "alpha": alpha,
                              "peak_at": float(res.offsets[name][int(np.nanargmax(v))] + res.center[j]),
                              "max": float(np.nanmax(v)), "mean_over_max": sharp})
            ax.set_xlabel(name + (" (deg)" if name.startswith("angle") else ""))
            ax.grid(alpha=0.3)
            if j == 0:
                ax.set_ylabel(("value / max" if params.normalize == "max" else "value") + f"\n{res.label}", fontsize=8)
            ax.set_title(f"{_label(r)}", fontsize=8)
        axes[k][-1].legend(fontsize=7)
    if params.title:
        fig.suptitle(params.title, fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / fig.get_figheight()) if params.title else None)
    return ReportOutput(tables={params.name: table}, figures={params.name: fig})


# --------------------------------------------------------------------------- overlays


def checkerboard(a: np.ndarray, b: np.ndarray, tiles: int = 8, windows=None) -> np.ndarray:
    """Alternate square tiles of two images of the same shape, each in its window (``windows``: a's and b's, default
    each one's :func:`display_window`)."""
    rows, cols = np.indices(a.shape) // max(1, min(a.shape) // tiles)
    wa, wb = windows or (display_window(a), display_window(b))
    return np.where((rows + cols) % 2 == 0, windowed(a, *wa), windowed(b, *wb))


def display_window(values: np.ndarray) -> tuple[float, float]:
    """The intensities drawn black and white in every registration figure and the viewer: the 0.5th and 99.5th
    percentiles of ``values`` (a few bright outliers, scalp fat or a vessel, do not darken the rest)."""
    return tuple(float(v) for v in np.percentile(values, (0.5, 99.5)))  # type: ignore[return-value]


def windowed(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """``x`` mapped from [lo, hi] onto [0, 1], clipped (an empty window: ``x - lo`` clipped, so that the rare
    pixels of a nearly constant image, a sparse mask, still show)."""
    return np.clip((x - lo) / (hi - lo if hi > lo else 1.0), 0.0, 1.0)


def overlay_rgb(fixed: np.ndarray, moving: np.ndarray, windows=None) -> np.ndarray:
    """Fixed in magenta, moving in green, each in its window (as :func:`checkerboard`): grey where they agree."""
    f, m = (windowed(x, *w) for x, w in zip((fixed, moving), windows or map(display_window, (fixed, moving))))
    return np.stack([f, m, f], axis=-1)


def planes(image) -> list[tuple[str, np.ndarray, float]]:
    """The 2D views of an image: a 2D image itself; the three central orthogonal planes of a volume (named by
    array axis: which one is axial depends on the acquisition). Each: a label, the flat pixel indices of the
    view (rows, cols; rows drawn downwards) and its aspect (row spacing / column spacing)."""
    grid = np.arange(image.data.size).reshape(image.shape)
    if image.dim == 2:
        return [("", grid, image.spacing[1] / image.spacing[0])]
    (nk, nj, ni), (sx, sy, sz) = image.shape, image.spacing
    return [("slice k (array axis 0)", grid[nk // 2], sy / sx), ("slice j (array axis 1)", grid[::-1, nj // 2], sz / sx),
            ("slice i (array axis 2)", grid[::-1, :, ni // 2], sz / sy)]


def before_after(fixed, moving, transform, flat: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The moving image on the fixed grid (or at its pixels ``flat``) before (the files' own placement: the
    identity) and after ``transform``, resampled in physical space, the moving minimum outside it."""
    fill = float(moving.data.min())
    return tuple(resample(moving, t, fixed, fill=fill, flat=flat)  # type: ignore[return-value]
                 for t in (RigidTransform.identity(tuple(fixed.center)), transform))


def draw_overlay(axes, fixed, moving, registration, title: str = "") -> None:
    """Per view of :func:`planes`, five panels on ``axes`` (rows x 5): fixed, moving, checkerboards before and after, colour
    overlay after; each image in the :func:`display_window` of all its pixels (a plane's own would tint aligned ones)."""
    windows = display_window(fixed.data), display_window(moving.data)
    for row, ((label, flat, aspect), (_, own, own_aspect)) in enumerate(zip(planes(fixed), planes(moving))):
        f = fixed.data.ravel()[flat]
        before, after = before_after(fixed, moving, registration.transform, flat)
        panels = [(windowed(f, *windows[0]), "fixed", aspect), (windowed(moving.data.ravel()[own], *windows[1]), "moving",
                   own_aspect), (checkerboard(f, before, windows=windows), "checkerboard before", aspect),
                  (checkerboard(f, after, windows=windows), "checkerboard after", aspect),
                  (overlay_rgb(f, after, windows), "after: fixed magenta, moving green", aspect)]
        for ax, (img, what, asp) in zip(axes[row], panels):
            ax.imshow(img, cmap="gray" if img.ndim == 2 else None, vmin=0, vmax=1, interpolation="nearest", aspect=asp)
            ax.set_title(f"{label}, {what}" if label else what, fontsize=8)
            ax.set_axis_off()
    flag = "" if registration.ok else f"  FLAGGED ({registration.summary()['flags']}): {registration.reason}"
    text = f"{title}  {registration.method}: {describe(registration.transform)} ({registration.seconds:.2f} s){flag}"
    axes[0][0].figure.text(0, -0.18 if len(axes) == 1 else 1.25, textwrap.fill(text, 250), fontsize=8,  # every panel
                           transform=axes[0][0].transAxes, color="#b00" if flag else "k", va="top" if len(axes) == 1 else "bottom")


def overlay_figure(pairs, **margins):
    """A figure of :func:`draw_overlay` per (fixed, moving, registration, title) of ``pairs``, one under the other
    (one row for a 2D image, three for a volume); ``margins``: ``top``, ``bottom``, ``hspace`` of the layout."""
    import matplotlib.pyplot as plt

    rows = [len(planes(fixed)) for fixed, *_ in pairs]
    fig, axes = plt.subplots(sum(rows), 5, figsize=(16, 3.9 * sum(rows)), squeeze=False)
    for k, (fixed, moving, registration, title) in enumerate(pairs):
        draw_overlay(axes[sum(rows[:k]): sum(rows[:k + 1])], fixed, moving, registration, title)
    fig.subplots_adjust(left=0.01, right=0.99, wspace=0.05, **margins)
    return fig


def registered_items(results, method: str, limit: int) -> list[tuple[Any, Any]]:
    """Up to ``limit`` (item result, its last registration whose method contains ``method``) pairs of
    the items that succeeded with a fixed and a moving image."""
    regs = [(r, [res.registration for res in _of_type(r, RegisterResult) if method in res.registration.method])
            for r in results if r.ok and r.final("fixed") is not None and r.final("moving") is not None]
    return [(r, found[-1]) for r, found in regs if found][:limit]


class OverlayParams(Params):
    name: str = Field("overlays", **_NAME)
    max_items: int = Field(12, ge=1, description="draw at most this many items")
    method: str = Field("", description="only registrations whose method contains this text (default: the last one)")


@report("registration_overlay", params=OverlayParams)
def registration_overlay_report(experiment, results, params: OverlayParams) -> ReportOutput:
    """Fixed, moving, checkerboards before/after and a colour overlay after registration, per item."""
    if not (chosen := registered_items(results, params.method, params.max_items)):
        return ReportOutput(notes=["no registered items to draw"])
    fig = overlay_figure([(r.final("fixed"), r.final("moving"), reg, _label(r)) for r, reg in chosen], top=0.95,
                         bottom=0.05, hspace=0.3)
    return ReportOutput(figures={params.name: fig})


# --------------------------------------------------------------------------- tables


class RegistrationTableParams(Params):
    name: str = Field("registrations", **_NAME)


@report("registration_table", params=RegistrationTableParams)
def registration_table_report(experiment, results, params: RegistrationTableParams) -> ReportOutput:
    """One row per item and method: estimate, truth, errors, TRE, self-check, time (in image units, degrees, s).

    Parameters by name (2D: angle, tx, ty; 3D: angle_x, angle_y, angle_z, tx, ty, tz); translations, their errors
    (``d_<name>``, ``d_translation``) and the TRE in the images' physical units (pixels for PNG, mm for volumes),
    angles and ``d_rotation`` in degrees, the time in seconds."""
    rows = []
    for r in results:
        evals = _of_type(r, EvaluateResult)
        for reg in (res.registration for res in _of_type(r, RegisterResult)):
            ev = next((e for e in evals if e.method == reg.method), None)
            row = {"item": r.item_id, "input": _label(r), "method": reg.method, **reg.transform.degrees()}
            if ev is not None:
                row.update({f"true_{k}": v for k, v in ev.truth.items()})
                row.update({k: v for k, v in ev.summary().items() if k not in ("method", "flagged", "seconds")})
            row.update({"ok": reg.ok, "reason": reg.reason, "iterations": reg.iterations,
                        "evaluations": reg.evaluations, "seconds": reg.seconds})
            rows.append(row)
        if not r.ok:
            rows.append({"item": r.item_id, "input": _label(r), "method": "", "ok": False, "reason": r.error})
    return ReportOutput(tables={params.name: rows})


class AccuracyParams(Params):
    name: str = Field("accuracy", **_NAME)
    threshold: float = Field(1.0, gt=0, description="success: mean TRE at most this (px; mm for a volume)")


def accuracy_rows(evaluations: list[tuple[str, Any]], threshold: float) -> list[dict[str, Any]]:
    """Summary rows per (group, method) from (group, EvaluateResult) pairs, plus an 'all' group per method."""
    groups: dict[tuple[str, str], list] = {}
    for group, ev in evaluations:
        groups.setdefault((group, ev.method), []).append(ev)
        groups.setdefault(("all", ev.method), []).append(ev)
    rows = []
    for (group, method), evs in sorted(groups.items(), key=lambda kv: (kv[0][0] != "all", kv[0][0], kv[0][1])):
        tre, secs = np.array([(e.tre_mean, e.seconds) for e in evs]).T
        success = tre <= threshold
        flagged = np.array([e.flagged for e in evs])
        rows.append({"pairs": group, "method": method, "cases": len(evs), "success_rate": float(success.mean()),
                     "median_tre": float(np.median(tre)), "p90_tre": float(np.percentile(tre, 90)),
                     "max_tre": float(tre.max()), "median_seconds": float(np.median(secs)),
                     "mean_seconds": float(secs.mean()), "flagged": int(flagged.sum()),
                     "failed_and_flagged": int((~success & flagged).sum()),
                     "failed_unflagged": int((~success & ~flagged).sum()),
                     "ok_but_flagged": int((success & flagged).sum())})
    return rows


@report("accuracy_summary", params=AccuracyParams)
def accuracy_summary_report(experiment, results, params: AccuracyParams) -> ReportOutput:
    """Success rate (mean TRE <= threshold), median TRE and time per method, per input pair and overall.
    A registration repeated across sweep points of a later stage (same pair, method, truth and estimate) counts once."""
    import matplotlib.pyplot as plt

    unique: dict[tuple, tuple[str, Any]] = {}
    for r, ev in ((r, ev) for r in results for ev in _of_type(r, EvaluateResult)):
        key = (*ev.truth.values(), *ev.errors.values())  # another contrast of one input: another estimate
        unique.setdefault((_label(r), ev.method, *(round(v, 9) for v in key)), (_label(r), ev))
    if not (evaluations := list(unique.values())):
        return ReportOutput(notes=["no evaluate results"])
    rows = accuracy_rows(evaluations, params.threshold)
    methods = sorted({ev.method for _, ev in evaluations})
    fig, axes = plt.subplots(1, 2, figsize=(12, 0.6 * len(methods) + 2.4))
    for k, method in enumerate(methods):
        tre, secs = np.array([(ev.tre_mean, ev.seconds) for _, ev in evaluations if ev.method == method]).T
        jitter = (np.random.default_rng(k).random(len(tre)) - 0.5) * 0.35
        axes[0].scatter(np.clip(tre, 1e-3, 1e3), k + jitter, s=9, alpha=0.6)
        axes[1].scatter(secs, k + jitter, s=9, alpha=0.6)
        axes[0].text(1.5e3, k, f"{(tre <= params.threshold).mean():.0%}", va="center", fontsize=8)
    for ax in axes:
        ax.set_yticks(range(len(methods)), methods, fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].set(xscale="log", xlim=(1e-3, 1e4))
    axes[0].axvline(params.threshold, color="r", lw=0.8)
    axes[0].set_xlabel("mean target registration error (px or mm, log); success rate on the right")
    axes[1].set_xlabel("seconds per registration")
    fig.tight_layout()
    return ReportOutput(tables={params.name: rows}, figures={params.name: fig})
