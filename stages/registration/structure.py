"""The outline-only tests of the self-check (``register.OUTLINE_TESTS``, ``register.check_outline``): how much of an
image's structure lies inside its outline (a mask or silhouette has none), and how far apart two objects' outlines lie
under a transform. Their thresholds and the scores on the corpus: docs/registration.md.

Written with numpy (box grows, a geodesic flood fill, ``image.gaussian_blur``): ``scipy.ndimage`` would cost a 2D
registration 0.12-0.18 s of import, as much as the registration."""

from __future__ import annotations

import numpy as np

from topomatch.stages.registration.image import Image, fill_holes, foreground_mask, gaussian_blur, grow, otsu_threshold
from topomatch.stages.registration.interpolation import resample
from topomatch.stages.registration.params import MetricSpec
from topomatch.stages.registration.transform import RigidTransform

CLOSING = 2.0
"""The content is closed by this many pixels (of the image :func:`object_mask` is given) before its holes are filled."""
BAND = 2.0
"""Half-width (pixels) of the outline band."""
ERODE = 3.0
"""The interior is the object eroded by this many pixels."""
SOLID = 0.9
""":func:`interior_spread` judges only an object at least this fraction of which is content (a mask is; a thresholded
image, with dark regions inside its object, is not)."""
GAP_BAND = 4.0
""":func:`outline_gap` compares the objects within this many pixels of the fixed outline."""
PLATEAU = 0.5
""":func:`two_class_residual` of an image at its exact minimum or maximum on at least this fraction of its pixels, with
more distinct intensities than a label map (``metric.discrete_levels``' default), is 0: two plateaus and a ramp
between (a soft mask), not an inside (twenty-third round)."""
RAMP_LEVELS = MetricSpec.model_fields["discrete_levels"].default


def once_per_image(compute):
    """``compute(image)`` computed once per :class:`Image` object and kept on it (an Image is frozen: its data do
    not change), so that the outline-only tests, which share their pieces, pay for each piece once."""
    key = f"_{compute.__name__}"

    def cached(image: Image):
        if key not in image.__dict__:
            object.__setattr__(image, key, compute(image))
        return image.__dict__[key]

    cached.__name__, cached.__doc__ = compute.__name__, compute.__doc__
    return cached


@once_per_image
def object_mask(image: Image) -> np.ndarray:
    """The object of ``image`` (bool, its shape): the content (:func:`~.image.foreground_mask`) closed by
    :data:`CLOSING` pixels with its holes filled. Computed once per image."""
    return fill_holes(~grow(~grow(foreground_mask(image), CLOSING), CLOSING))


@once_per_image
def analysed_copy(image: Image) -> Image:
    """``image`` block-averaged by 2 along axes of at least 48 pixels: the copy :func:`interior_structure` and
    :func:`interior_spread` analyse (made once per image, so that its :func:`object_mask` is computed once too)."""
    return image.shrink([2 if n >= 48 else 1 for n in image.data.shape[::-1]])


def outline_in_view(image: Image, other: Image | None = None, transform=None) -> float:
    """Fraction of the boundary of the object (:func:`object_mask`) that is its outline inside the grid rather
    than the grid's border cutting it (unit-free in [0, 1]): the physical area (length in 2D) of the pixel faces
    between object and background over that plus the object's pixel faces on the grid's border. 1 for an object
    clear of the border, near 0 for one that fills the grid; NaN for an empty object. With ``other`` and
    ``transform`` (this image's points to ``other``'s), an outline face whose centre lands outside ``other``'s grid
    counts as cut too: the other image does not see it (a cropped partner; fourteenth round)."""
    obj = object_mask(image)
    spacing = np.asarray(image.spacing, dtype=np.float64)[::-1]  # array axis order
    face = np.prod(spacing) / spacing  # area of a pixel face normal to each array axis
    inside, cut = 0.0, sum(face[a] * np.count_nonzero(np.take(obj, [0, -1], axis=a)) for a in range(obj.ndim))
    for a in range(obj.ndim):
        faces = np.argwhere(np.diff(obj, axis=a)).astype(np.float64)
        faces[:, a] += 0.5  # array indices of the face centres, half-way between their two pixels
        index = None if other is None else other.continuous_index(transform.apply(image.physical(faces[:, ::-1])))
        seen = len(faces) if index is None else int(np.count_nonzero(  # centres on the other grid's pixels
            np.all((index >= -0.5) & (index <= np.asarray(other.size) - 0.5), axis=1)))
        inside, cut = inside + face[a] * seen, cut + face[a] * (len(faces) - seen)
    return float(inside / (inside + cut)) if inside + cut > 0 else float("nan")


@once_per_image
def plateau_share(image: Image) -> float:
    """Share of the pixels above the image's minimum (a label map's object, as the label test makes it) equal to
    their next neighbour along every axis: exact plateaus (label maps 0.19-0.94 on the corpus and the kind attack; an
    image with noise 0, a uint8 volume 0.0001)."""
    equal = np.ones(image.data.shape, dtype=bool)
    for axis in range(image.data.ndim):
        x, e = np.moveaxis(image.data, axis, 0), np.zeros(image.data.shape, dtype=bool)
        np.moveaxis(e, axis, 0)[:-1] = x[:-1] == x[1:]
        equal &= e
    obj = image.data > image.data.min()
    return float(equal[obj].mean()) if obj.any() else 0.0


def distinct_levels(image: Image, limit: int, samples: int = 65536) -> int:
    """How many distinct intensities ``image`` holds, counted up to ``limit + 1`` on an evenly strided subset of at
    most ``samples`` voxels (an image with noise shows thousands there; a label map or thresholded mask its few)."""
    flat = image.data.ravel()
    values = np.unique(flat[::max(1, flat.size // samples)])
    return int(min(values.size, limit + 1))


@once_per_image
def interior_structure(image: Image) -> float:
    """Mean gradient magnitude inside the object over its mean on the object's outline (unit-free, >= 0).

    On :func:`analysed_copy`, its object (:func:`object_mask`) and its gradient smoothed by one pixel; the outline
    band is :data:`BAND` pixels either side of the object's edge, the interior the object eroded by :data:`ERODE`.
    NaN when either is empty (an object smaller than the band, or filling the grid)."""
    small = analysed_copy(image)
    obj = object_mask(small)
    band, inside = grow(obj, BAND) & grow(~obj, BAND), ~grow(~obj, ERODE)
    if band.sum() < 10 or inside.sum() < 10:
        return float("nan")
    gradient = np.gradient(gaussian_blur(small.data, [1.0] * small.dim, truncate=3.0)) if min(small.data.shape) > 1 else [np.zeros_like(small.data)]
    magnitude = np.sqrt(sum(g ** 2 for g in gradient))
    edge = float(np.mean(magnitude[band]))
    return float(np.mean(magnitude[inside]) / edge) if edge > 0 else float("nan")


@once_per_image
def interior_spread(image: Image) -> float:
    """Spread of the intensities inside the object over the object's contrast with its background (unit-free,
    >= 0): ``(q90 - q10) / |median(core) - median(background core)|`` on :func:`analysed_copy`, the core being the
    Otsu content (:func:`~.image.foreground_mask`, holes not filled) and the background core the rest, each eroded
    by one pixel; a noisy mask scores 2.56 times its (block-averaged) noise over its contrast, a binary image 0
    (docs/registration_history.md, ``outline``, fourth round). NaN when the content fills the grid, either core has fewer
    than 10 pixels, or less than :data:`SOLID` of the object (:func:`object_mask`) is content (a thresholded image:
    structure inside)."""
    small = analysed_copy(image)
    content = foreground_mask(small)
    core, back = ~grow(~content, 1.0), ~grow(content, 1.0)
    obj = object_mask(small)
    if core.sum() < 10 or back.sum() < 10 or (content & obj).sum() < SOLID * obj.sum():
        return float("nan")
    low, middle, high = np.percentile(small.data[core], [10, 50, 90])
    contrast = abs(float(middle) - float(np.median(small.data[back])))
    return float((high - low) / contrast) if contrast > 0 else float("nan")


def two_class_residual(image: Image) -> float:
    """The worse of ``image``'s two Otsu classes' variance over the squared difference of their means (an inverse
    squared contrast-to-noise ratio, unit-free): a mask or silhouette with noise s and contrast D scores (s / D)^2
    whatever fraction of the grid it fills (2 % noise: 4e-4), an image with an inside far more (brain sections >= 0.004
    on the corpus; docs/registration_history.md, ``outline``, sixth round). Judged only where :func:`interior_structure` and
    :func:`interior_spread` cannot (both NaN: an object that fills the grid, a tight field of view; both are kept on
    the image); NaN elsewhere; 0 for two exact plateaus and a ramp (:data:`PLATEAU`)."""
    if not (np.isnan(interior_structure(image)) and np.isnan(interior_spread(image))):
        return float("nan")
    data = image.data.ravel()
    upper = data > otsu_threshold(image.data)
    if upper.all() or not upper.any() or (contrast := data[upper].mean() - data[~upper].mean()) <= 0:
        return float("nan")
    extreme = (data <= data.min() + 1e-6 * contrast) | (data >= data.max() - 1e-6 * contrast)
    if np.mean(extreme) >= PLATEAU and distinct_levels(image, RAMP_LEVELS) > RAMP_LEVELS:
        return 0.0  # two plateaus and a ramp between: a soft mask
    return float(max(data[upper].var(), data[~upper].var()) / contrast ** 2)


def outline_gap(fixed: Image, moving: Image, transform: RigidTransform) -> float:
    """Mean distance (physical units) between the two objects' outlines (:func:`object_mask`) with ``moving``
    mapped by ``transform`` (``moving(T(p))`` at fixed p): the area (volume) between them over the fixed outline's
    length (area, the indicator's total variation), within :data:`GAP_BAND` pixels of the fixed outline (outlines
    farther apart saturate: the test needs to know a gap of a pixel or two) and where the mapped moving object is
    defined. A mask grown by r against itself scores r; identical objects score about a third of a pixel after a
    rotation (the pixel grid); NaN when the fixed object has no outline there."""
    fixed_object, moving_object = object_mask(fixed), object_mask(moving)
    near = np.flatnonzero(grow(fixed_object, GAP_BAND) & grow(~fixed_object, GAP_BAND))
    mapped = resample(moving.with_data(moving_object.astype(np.float64)), transform, fixed, fill=np.nan, flat=near)
    defined = np.isfinite(mapped)
    slope = np.sqrt(sum(g ** 2 for g in np.gradient(fixed_object.astype(np.float64), *fixed.spacing[::-1])))
    if (outline := float(slope.ravel()[near][defined].sum())) <= 0:
        return float("nan")
    between = float(np.abs(fixed_object.ravel()[near][defined] - mapped[defined]).sum())
    return between / outline
