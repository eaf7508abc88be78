"""Interactive slice viewer of a registration for the run pages: fixed and moving with an opacity slider.

For a 2D pair one view, for a volume three orthogonal slices (array axes k, j, i; which is axial depends on the
acquisition, so they are named by axis) with a slider each; for every view the moving image resampled on the fixed grid
**before** (the files' own placement) or **after** the registration, blended over the fixed image by an **opacity**
slider, in grey (cross-fade) or in colour (fixed magenta, moving green: grey where they agree). Written by hand in a few
lines of plain JavaScript on canvases (no library: a blend of two 8-bit images is all it draws); the images travel in
the page as base64 bytes, each axis reduced to at most ``MAX_SIDE`` samples (``MAX_SAMPLES`` in all), so the page works
offline from the run folder."""

from __future__ import annotations

import base64
import html
import json

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import Params, ReportOutput, report
from topomatch.stages.registration.register import describe
from topomatch.stages.registration.reports import before_after, display_window, registered_items, windowed

#: Largest number of samples per axis, and in all, kept in a page (a volume of 128 x 128 x 62 voxels
#: becomes about 300,000 samples: three images of that size travel as about 1.2 MB of base64).
MAX_SIDE = 160
MAX_SAMPLES = 300_000

_SCRIPT = """
<script>(function(){
var root=document.getElementById(%(id)s), d=%(payload)s, sh=d.shape, n=sh.length;
function bytes(s){var b=atob(s),a=new Uint8Array(b.length);for(var i=0;i<b.length;i++)a[i]=b.charCodeAt(i);return a;}
var F=bytes(d.fixed), M={before:bytes(d.before),after:bytes(d.after)};
var views=n==2?[{axis:-1,w:sh[1],h:sh[0],sx:d.spacing[1],sy:d.spacing[0]}]:
 [{axis:0,w:sh[2],h:sh[1],sx:d.spacing[2],sy:d.spacing[1]},
  {axis:1,w:sh[2],h:sh[0],sx:d.spacing[2],sy:d.spacing[0]},
  {axis:2,w:sh[1],h:sh[0],sx:d.spacing[1],sy:d.spacing[0]}];
function at(v,s,x,y){ if(n==2)return y*sh[1]+x;
 if(v.axis==0)return (s*sh[1]+y)*sh[2]+x;
 if(v.axis==1)return ((sh[0]-1-y)*sh[1]+s)*sh[2]+x;
 return ((sh[0]-1-y)*sh[1]+x)*sh[2]+s;}
function q(sel){return root.querySelector(sel);}
function draw(){var a=+q('.opacity').value/100, when=q('.when:checked').value, colour=q('.colour').checked,
 mv=M[when], drawn=0;
 views.forEach(function(v,k){var c=root.querySelectorAll('canvas')[k], s=n==2?0:+root.querySelectorAll('.slice')[k].value,
  g=c.getContext('2d'), img=g.createImageData(v.w,v.h), p=img.data;
  for(var y=0;y<v.h;y++)for(var x=0;x<v.w;x++){var i=at(v,s,x,y),f=F[i],m=mv[i],o=4*(y*v.w+x);
   if(colour){p[o]=f*(1-a)+f*a;p[o+1]=f*(1-a)+m*a;p[o+2]=f*(1-a)+f*a;}
   else{p[o]=p[o+1]=p[o+2]=f*(1-a)+m*a;} p[o+3]=255; drawn+=(p[o]|p[o+1])>0;}
  g.putImageData(img,0,0);});
 root.setAttribute('data-drawn',drawn);}
root.querySelectorAll('input').forEach(function(e){e.addEventListener('input',draw);});
draw();})();</script>
"""


def _bytes(a: np.ndarray, lo: float, hi: float) -> str:
    """base64 of ``a`` mapped from [lo, hi] to 0..255 (uint8, C order)."""
    u = windowed(np.asarray(a, dtype=np.float64), lo, hi)
    return base64.b64encode(np.round(255 * u).astype(np.uint8).tobytes()).decode()


def slice_viewer(fixed: np.ndarray, before: np.ndarray, after: np.ndarray, spacing, title: str, view_id: str) -> str:
    """An HTML fragment: the viewer of one registration (module docstring) of ``fixed`` and the moving image
    resampled on its grid ``before`` and ``after`` registration, (H, W) or (K, J, I) each; ``spacing``: per array
    axis (same order), for the aspect ratio."""
    fixed = np.asarray(fixed, dtype=np.float64)
    if fixed.ndim not in (2, 3) or before.shape != fixed.shape or after.shape != fixed.shape:
        raise ValueError(f"slice_viewer: fixed {fixed.shape}, before {before.shape}, after {after.shape}: "
                         "need three 2D or three 3D arrays of one shape")
    step = [max(1, -(-s // MAX_SIDE)) for s in fixed.shape]
    while np.prod([-(-s // k) for s, k in zip(fixed.shape, step)]) > MAX_SAMPLES:  # thin the longest axis
        longest = int(np.argmax([s * sp / k for s, sp, k in zip(fixed.shape, spacing, step)]))
        step[longest] += 1
    keep = tuple(slice(None, None, k) for k in step)
    fixed, before, after = (np.ascontiguousarray(np.asarray(a)[keep]) for a in (fixed, before, after))
    spacing = [float(s) * k for s, k in zip(spacing, step)]
    lo, hi = display_window(fixed)
    mlo, mhi = display_window(np.concatenate([before.ravel(), after.ravel()]))
    payload = {"shape": list(fixed.shape), "spacing": spacing, "fixed": _bytes(fixed, lo, hi),
               "before": _bytes(before, mlo, mhi), "after": _bytes(after, mlo, mhi)}
    views = [(fixed.shape[1], fixed.shape[0], spacing[1], spacing[0], "")] if fixed.ndim == 2 else [
        (fixed.shape[2], fixed.shape[1], spacing[2], spacing[1], "k (array axis 0)"),
        (fixed.shape[2], fixed.shape[0], spacing[2], spacing[0], "j (array axis 1)"),
        (fixed.shape[1], fixed.shape[0], spacing[1], spacing[0], "i (array axis 2)")]
    panels = []
    for k, (w, h, sx, sy, label) in enumerate(views):
        scale = 320 / max(w * sx, h * sy)
        slider = "" if fixed.ndim == 2 else (
            f"<br><label>{label} slice <input class='slice' type='range' min='0' max='{fixed.shape[k] - 1}' "
            f"value='{fixed.shape[k] // 2}'></label>")
        panels.append(f"<div style='display:inline-block;margin:4px;vertical-align:top'><canvas width='{w}' "
                      f"height='{h}' style='width:{w * sx * scale:.0f}px;height:{h * sy * scale:.0f}px;"
                      f"image-rendering:pixelated;border:1px solid #ccc'></canvas>{slider}</div>")
    name = html.escape(view_id)
    controls = (f"<div><b>{html.escape(title)}</b> &nbsp; <label>moving opacity <input class='opacity' type='range' "
                f"min='0' max='100' value='50'></label> &nbsp; <label><input class='when' type='radio' "
                f"name='{name}-when' value='before'> before</label> <label><input class='when' type='radio' "
                f"name='{name}-when' value='after' checked> after</label> &nbsp; <label><input class='colour' "
                f"type='checkbox'> colour (fixed magenta, moving green)</label></div>")
    script = _SCRIPT % {"id": json.dumps(view_id), "payload": json.dumps(payload)}
    return f"<div id='{name}' class='slice-viewer'>{controls}{''.join(panels)}</div>{script}"


class SliceViewerParams(Params):
    name: str = Field("slices", pattern=r"^[A-Za-z0-9_.-]+$", description="name of the view")
    max_items: int = Field(6, ge=1, description="show at most this many registrations")
    method: str = Field("", description="only registrations whose method contains this text (default: the last one)")


@report("registration_viewer", params=SliceViewerParams)
def registration_viewer_report(experiment, results, params: SliceViewerParams) -> ReportOutput:
    """Interactive viewers of registered pairs: fixed and moving (before or after) with an opacity slider."""
    fragments = []
    for r, reg in registered_items(results, params.method, params.max_items):
        fixed = r.final("fixed")
        before, after = before_after(fixed, r.final("moving"), reg.transform)
        title = f"{r.item_id}: {reg.method}, {describe(reg.transform)}"  # the item: its input and sweep point
        fragments.append(slice_viewer(fixed.data, before, after, fixed.spacing[::-1], title,
                                      f"{params.name}-{len(fragments)}"))
    if not fragments:
        return ReportOutput(notes=["no registered pair to show"])
    return ReportOutput(html={params.name: "".join(fragments)},
                        notes=["Move the opacity slider to fade the moving image over the fixed one; 'before' shows "
                               "the files' own placement, 'after' the registration's."])
