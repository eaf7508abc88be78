"""The registration slice viewer of the run pages (plain JavaScript on canvases), in headless Chromium."""

from __future__ import annotations

import base64
import json
import re

import numpy as np
import pytest

from browser import dump_dom, needs_chromium, screenshot
from topomatch.stages.registration.viewer import MAX_SAMPLES, MAX_SIDE, slice_viewer


def _page(tmp_path, fragment):
    page = tmp_path / "viewer.html"
    page.write_text("<!doctype html><html><head><meta charset='utf-8'><script>window.addEventListener('error',"
                    "function(e){document.documentElement.setAttribute('data-js-errors',e.message)});</script></head>"
                    f"<body>{fragment}</body></html>")
    return page


def test_fragment_carries_reduced_volumes_and_refuses_mismatched_shapes():
    vol = np.random.default_rng(0).random((40, 400, 90))
    html = slice_viewer(vol, vol, vol, (3.0, 1.0, 1.0), "t", "v0")
    assert html.count("<canvas") == 3 and html.count("class='slice'") == 3
    shape = [int(x) for x in re.search(r'"shape": \[(\d+), (\d+), (\d+)\]', html).groups()]
    assert max(shape) <= MAX_SIDE and MAX_SAMPLES / 4 < np.prod(shape) <= MAX_SAMPLES
    with pytest.raises(ValueError, match="one shape"):
        slice_viewer(vol, vol[:10], vol, (1, 1, 1), "t", "v1")


@needs_chromium
def test_volume_viewer_draws_three_orthogonal_slices_without_errors(tmp_path):
    k, j, i = np.mgrid[:30, :50, :60]
    fixed = ((k - 15) ** 2 / 100 + (j - 25) ** 2 / 400 + (i - 30) ** 2 / 600 < 1).astype(float)
    moved = np.roll(fixed, 4, axis=2)
    page = _page(tmp_path, slice_viewer(fixed, moved, fixed, (3.0, 1.0, 1.0), "ellipsoid", "vol"))
    dom = dump_dom(page)
    assert re.search(r'data-js-errors="', dom) is None
    drawn = int(re.search(r'data-drawn="(\d+)"', dom).group(1))
    assert drawn > 0.3 * (50 * 60)  # the ellipsoid's slices are drawn (fixed and moving blended)
    assert screenshot(page, "registration_viewer_3d.png", tmp_path).stat().st_size > 5_000


@needs_chromium
def test_registration_demo_page_has_its_slice_viewer(tmp_path):
    from topomatch.pipeline.config import load_experiment
    from topomatch.pipeline.runner import run_experiment
    from tests_paths import REPO_ROOT

    run = run_experiment(load_experiment(REPO_ROOT / "configs" / "registration" / "demo.yaml"), out_root=tmp_path)
    view = run.run_dir / "views" / "slices.html"
    dom = dump_dom(view)
    assert re.search(r'data-js-errors="', dom) is None and int(re.search(r'data-drawn="(\d+)"', dom).group(1)) > 1000
    assert "slice-viewer" in (run.run_dir / "index.html").read_text()


def test_volume_report_resamples_in_physical_space():
    """The report's 'after' volume is the moving volume brought back by the registration's transform:
    a volume shifted by 4 voxels along i and 'registered' by the true shift looks like the fixed one."""
    from types import SimpleNamespace

    from topomatch.stages.registration.image import Image
    from topomatch.stages.registration.register import RegisterResult
    from topomatch.stages.registration.transform import RigidTransform
    from topomatch.stages.registration.viewer import SliceViewerParams, registration_viewer_report

    k, j, i = np.mgrid[:20, :30, :40]
    blob = np.exp(-((k - 10) ** 2 / 20 + (j - 15) ** 2 / 40 + (i - 20) ** 2 / 60))
    fixed = Image(blob, spacing=(1.0, 1.0, 2.0))
    moving = Image(np.roll(blob, 4, axis=2), spacing=(1.0, 1.0, 2.0))  # 4 voxels of 1 mm along x (axis i)
    truth = RigidTransform((0, 0, 0, 4.0, 0, 0), tuple(fixed.center))
    registration = SimpleNamespace(transform=truth, method="test")
    item = SimpleNamespace(ok=True, input_label="blob", item_id="blob", results={"register": RegisterResult(
        registration)}, final=lambda key: {"fixed": fixed, "moving": moving}.get(key))
    out = registration_viewer_report(None, [item], SliceViewerParams(name="v"))
    html = out.html["v"]
    payload = json.loads(re.search(r"var root=.*?, d=(\{.*?\}), sh=", html, re.S).group(1))
    fixed_bytes, after = (np.frombuffer(base64.b64decode(payload[key]), np.uint8).reshape(payload["shape"])
                          for key in ("fixed", "after"))
    before = np.frombuffer(base64.b64decode(payload["before"]), np.uint8).reshape(payload["shape"])
    inner = (slice(2, -2), slice(2, -2), slice(6, -6))
    assert np.abs(after[inner].astype(int) - fixed_bytes[inner]).mean() < 3 < np.abs(
        before[inner].astype(int) - fixed_bytes[inner]).mean()


def test_overlay_windows_each_image_like_the_viewer():
    """The overlay figure's colours (``reports.overlay_rgb``): grey (R = G = B) where the two images agree, and each
    image windowed to its 0.5th-99.5th percentiles, so that one bright outlier pixel (scalp fat) leaves a ramp's
    middle at mid-grey instead of near black (min-max scaling put it at 0.0005)."""
    from topomatch.stages.registration.reports import overlay_rgb

    ramp = np.linspace(0.0, 1.0, 10_000).reshape(100, 100)
    rgb = overlay_rgb(ramp, ramp)
    assert np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 1], rgb[..., 2])
    bright = ramp.copy()
    bright[0, 0] = 1000.0
    middle = overlay_rgb(bright, ramp)[50, 0]
    assert middle[0] == pytest.approx(0.5, abs=0.01) and middle[1] == pytest.approx(0.5, abs=0.01)
    assert overlay_rgb(bright, ramp).min() == 0.0 and overlay_rgb(bright, ramp).max() == 1.0


def _drawn_overlay(d: int, fixed, moving, transform, flags=()):
    """``draw_overlay`` of a registration ending at ``transform`` with ``flags``, on the rows a ``d``-D image takes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from topomatch.stages.registration.register import Registration
    from topomatch.stages.registration.reports import draw_overlay

    reg = Registration(transform=transform, value=0.0, flags=tuple(flags), method="m", seconds=0.0, iterations=0,
                       evaluations=0, stop_reason="")
    fig, axes = plt.subplots(1 if d == 2 else 3, 5, squeeze=False)
    draw_overlay(axes, fixed, moving, reg)
    return fig, axes


@pytest.mark.parametrize("d", [2, 3])
def test_an_aligned_overlay_is_grey_where_the_fields_overlap(d):
    """``draw_overlay`` windows each image over all its pixels, not over each drawn plane: a moving image that is the
    fixed one shifted by whole pixels, registered by that shift, draws grey (R = G) wherever both fields of view reach,
    in every plane, although the resampled plane holds the moving minimum where its field of view ends (with a plane's
    own percentiles that fill moved the window and tinted the aligned overlay green)."""
    import matplotlib.pyplot as plt

    from topomatch.stages.registration.image import Image
    from topomatch.stages.registration.transform import RigidTransform

    data = np.random.default_rng(d).normal(size=(24, 26, 22)[:d]) - 3.0  # negative values: the fill is not 0
    fixed = Image(data)
    shift = 5  # whole pixels along the last axis (x), wrapped: fixed(p) = moving(p + 5 x) for the first n - 5 columns
    moving = Image(np.roll(data, shift, axis=-1))  # the same intensities: the same window as the fixed image's
    transform = RigidTransform((0.0,) * (3 * d - 3 - d) + (float(shift),) + (0.0,) * (d - 1), tuple(fixed.center))
    fig, axes = _drawn_overlay(d, fixed, moving, transform)
    for row in axes:
        rgb = row[4].get_images()[0].get_array()
        inside = rgb[:, : -shift - 1]  # columns whose moved point is in the field (slice i: its columns are y, all in)
        assert np.allclose(inside[..., 0], inside[..., 1], atol=1e-9)
    plt.close(fig)


@pytest.mark.parametrize("d", [2, 3])
def test_a_flagged_overlay_names_every_flag_and_its_whole_reason(d):
    """The caption carries the whole reason, wrapped (it was cut at 100 characters: a third flag's words were lost),
    below a 2D row and above a volume's first row."""
    import matplotlib.pyplot as plt

    from topomatch.stages.registration.image import Image
    from topomatch.stages.registration.register import Flag
    from topomatch.stages.registration.transform import RigidTransform

    image = Image(np.random.default_rng(d).normal(size=(12, 14, 10)[:d]))
    flags = tuple(Flag(name, f"{name} says " + "words " * 40 + f"end of {name}") for name in ("gain", "capture", "mirror"))
    fig, _ = _drawn_overlay(d, image, image, RigidTransform.identity(tuple(image.center)), flags)
    (caption,) = [t.get_text() for t in fig.texts]
    flat = " ".join(caption.split())
    assert "FLAGGED (gain,capture,mirror)" in flat and all(f"end of {n}" in flat for n in ("gain", "capture", "mirror"))
    assert "\n" in caption and max(map(len, caption.splitlines())) <= 250
    plt.close(fig)
