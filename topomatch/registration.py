"""Rigid registration of two images or two volumes: the Python API behind ``topomatch register``.

:func:`register` picks 2D or 3D from its inputs. Two 2D images (or slices: ``fixed_slice`` /
``moving_slice``) run ``load_pair -> register`` (or ``register`` alone on in-memory images)
through the engine's runner, exactly as ``topomatch register`` and a config do, with the
``register`` stage's defaults for everything not given. The transform is in ITK's convention:
``T(x) = R(angle)(x - c) + c + t``, x = (column, row) in pixels, c the fixed image's centre,
``moving(T(x)) ~ fixed(x)``. :func:`write_registration_files` writes what ``--out`` writes.

Two 3D volumes (NIfTI, MetaImage, NRRD, DICOM file or series folder, or
:class:`~topomatch.stages.registration.volume.Volume` objects) run the ``register_3d`` stage with the
same options: a :class:`VolumeRegistrationOutcome` in physical LPS millimetres, SimpleITK's
``Euler3DTransform`` convention (:data:`CONVENTION_3D`); :func:`write_volume_registration_files`
writes what ``--out`` writes for them.
"""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from topomatch.pipeline.cli_options import Option
from topomatch.pipeline.config import chain_with
from topomatch.pipeline.errors import InputError, StageError
from topomatch.pipeline.files import atomic_write_bytes, atomic_write_text
from topomatch.pipeline.item import run_stages
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.io import read_image as _read_image
from topomatch.stages.registration.register import Registration, RegisterParams
from topomatch.stages.registration.volume import Volume

#: The options of a registration, shared by :func:`register` (keyword -> field) and ``topomatch register``.
REGISTER_OPTIONS = {
    "metric": Option("register.metric.name", flag="--metric"),
    "alpha": Option("register.metric.alpha"),
    "weights": Option("register.metric.weights"),
    "optimizer": Option("register.optimizer.name", flag="--optimizer"),
    "seed": Option("register.seed"),
    "fixed_slice": Option("load_pair.fixed_slice"),
    "moving_slice": Option("load_pair.moving_slice"),
}

CONVENTION = "ITK: T(x) = R(angle)(x - c) + c + t, x = (col, row) px, moving(T(x)) ~ fixed(x)"
CONVENTION_3D = ("ITK Euler3DTransform: T(p) = R (p - c) + c + t, R = Rz(az) Rx(ax) Ry(ay), p physical LPS mm, "
                 "c = centre of the fixed volume, fixed(p) ~ moving(T(p)); matrix = 4x4 fixed-to-moving map")


@dataclass(frozen=True, eq=False)
class RegistrationOutcome:
    """The result of one registration, with the fields ``topomatch register --json`` prints.

    JSON fields (:meth:`to_dict`): ``fixed``, ``moving`` (names), ``convention``, ``tx``, ``ty`` (pixels),
    ``angle`` (degrees), ``center`` (c, pixels), ``metric``, ``alpha``, ``method``, ``objective`` (the
    measure at the result), ``iterations``, ``evaluations``, ``seconds``, ``ok`` (the self-check
    passed) and ``reason`` (why not). Besides them: ``registration`` (the full
    :class:`~topomatch.stages.registration.register.Registration`, with the optimiser's history),
    ``fixed_image`` and ``moving_image``.
    """

    fixed: str
    moving: str
    convention: str
    tx: float
    ty: float
    angle: float
    center: list[float]
    metric: str
    alpha: float
    method: str
    objective: float
    iterations: int
    evaluations: int
    seconds: float
    ok: bool
    reason: str
    registration: Registration = field(repr=False)
    fixed_image: Image = field(repr=False)
    moving_image: Image = field(repr=False)

    JSON_FIELDS = ("fixed", "moving", "convention", "tx", "ty", "angle", "center", "metric", "alpha", "method",
                   "objective", "iterations", "evaluations", "seconds", "ok", "reason")

    def to_dict(self) -> dict[str, Any]:
        """The JSON fields as a plain dict."""
        return {k: getattr(self, k) for k in self.JSON_FIELDS}


@dataclass(frozen=True, eq=False)
class VolumeRegistrationOutcome:
    """The result of one 3D registration, with the fields ``topomatch register --json`` prints for volumes.

    JSON fields (:meth:`to_dict`): ``fixed``, ``moving``, ``dimension`` (3), ``convention``,
    ``parameters`` (SimpleITK's ``Euler3DTransform`` order: angles x, y, z in radians, translation in
    mm), ``angles`` (degrees), ``translation`` (mm), ``center`` (c, mm), ``matrix`` (the 4 x 4
    homogeneous fixed-to-moving matrix, row-major, physical LPS mm), ``metric``, ``alpha``, ``method``,
    ``objective``, ``iterations``, ``evaluations``, ``overlap`` (fraction of fixed samples inside the
    moving volume), ``seconds``, ``ok``, ``reason``. Besides them: ``registration`` (the full
    :class:`~topomatch.stages.registration.register3d.VolumeRegistration`), ``fixed_volume``,
    ``moving_volume``.
    """

    fixed: str
    moving: str
    dimension: int
    convention: str
    parameters: list[float]
    angles: list[float]
    translation: list[float]
    center: list[float]
    matrix: list[list[float]]
    metric: str
    alpha: float
    method: str
    objective: float
    iterations: int
    evaluations: int
    overlap: float
    seconds: float
    ok: bool
    reason: str
    registration: Any = field(repr=False)
    fixed_volume: Volume = field(repr=False)
    moving_volume: Volume = field(repr=False)

    JSON_FIELDS = ("fixed", "moving", "dimension", "convention", "parameters", "angles", "translation", "center",
                   "matrix", "metric", "alpha", "method", "objective", "iterations", "evaluations", "overlap",
                   "seconds", "ok", "reason")

    to_dict = RegistrationOutcome.to_dict


def read_image(path: str | Path, *, slice: int | None = None) -> Image:
    """A 2D image (PNG, TIFF, NIfTI, DICOM, MetaImage, NRRD), or one slice of a volume (along its first axis).

    Raises
    ------
    InputError
        Missing, unreadable or unusable file (names it).
    """
    return _read_image(path, slice_index=slice)


def read_volume(path: str | Path) -> Volume:
    """A 3D volume (NIfTI, MetaImage, NRRD, DICOM file or series folder) with its physical geometry.

    Raises
    ------
    InputError
        Missing, unreadable or unusable file or folder (names it).
    """
    from topomatch.stages.registration.volume_io import read_volume as _read_volume

    return _read_volume(path)


def register(fixed: Image | Volume | str | Path, moving: Image | Volume | str | Path, *, metric: str | None = None,
             alpha: float | None = None, weights: str | None = None, optimizer: str | None = None,
             seed: int | None = None, fixed_slice: int | None = None,
             moving_slice: int | None = None) -> RegistrationOutcome | VolumeRegistrationOutcome:
    """Register ``moving`` to ``fixed`` (rigid): 2D images, image files, 3D volumes or volume files.

    Two 3D volumes (files, a DICOM series folder, or :class:`Volume` objects) without slices are
    registered in 3D (6 parameters, physical mm; a :class:`VolumeRegistrationOutcome`); anything
    else in 2D (a :class:`RegistrationOutcome`).

    Parameters
    ----------
    fixed, moving : Image, Volume or path
    metric : {'jt', 'jr', 'mi', 'tmi'}, optional
        Jensen-Tsallis (the default of the ``register`` stage, thesis ch. 2), Jensen-Renyi, mutual
        information, Tsallis MI.
    alpha : float, optional
        Entropy order of jt, jr, tmi (default 2).
    weights : {'histogram', 'uniform'}, optional
        Jensen weights (default: the reference histogram).
    optimizer : {'spsa', 'powell'}, optional
        Default SPSA.
    seed : int, optional
        Seed of SPSA and of the sample subsets (the same seed gives the same result).
    fixed_slice, moving_slice : int, optional
        Files only: the slice of a 3D volume.

    Returns
    -------
    RegistrationOutcome or VolumeRegistrationOutcome
        ``ok`` is False, with a ``reason``, when the self-check flags the result.

    Raises
    ------
    InputError
        An unreadable or unusable image (names it).
    ConfigError
        An option out of range.
    StageError
        The registration could not run.
    """
    given = {"metric": metric, "alpha": alpha, "weights": weights, "optimizer": optimizer, "seed": seed,
             "fixed_slice": fixed_slice, "moving_slice": moving_slice}
    overrides: dict[str, dict[str, Any]] = {}
    for keyword, value in given.items():
        if value is not None:
            stage_name, *path = REGISTER_OPTIONS[keyword].path.split(".")
            target = overrides.setdefault(stage_name, {})
            for part in path[:-1]:
                target = target.setdefault(part, {})
            target[path[-1]] = value
    return register_with(fixed, moving, overrides)


def is_volume_pair(fixed: Image | Volume | str | Path, moving: Image | Volume | str | Path,
                   overrides: dict[str, dict[str, Any]] | None = None) -> bool:
    """Whether :func:`register` treats the inputs as 3D volumes: two :class:`Volume` objects, or two
    files (or DICOM folders) of 3 or more dimensions and no slice option. Unreadable files give False
    (the 2D reader then reports them as before)."""
    if isinstance(fixed, Volume) or isinstance(moving, Volume):
        return True
    if isinstance(fixed, Image) or isinstance(moving, Image) or "load_pair" in (overrides or {}):
        return False
    from topomatch.stages.registration.volume_io import image_dimension

    try:
        return min(image_dimension(fixed), image_dimension(moving)) >= 3
    except InputError:
        return False


def register_volumes_with(fixed: Volume | str | Path, moving: Volume | str | Path,
                          overrides: dict[str, dict[str, Any]]) -> VolumeRegistrationOutcome:
    """3D :func:`register` with the options as ``{stage: {param: value}}``; the 2D ``register`` stage's
    options (metric, alpha, weights, optimizer, seed) apply to ``register_3d``."""
    from topomatch.stages.registration.register3d import Register3DParams
    from topomatch.stages.registration.volume_io import read_volume_pair

    if "load_pair" in overrides:
        raise InputError(None, "fixed_slice / moving_slice apply to 2D registration of volume slices, not to 3D volumes")
    options = {**overrides.get("register", {}), **overrides.get("register_3d", {})}
    if isinstance(fixed, Volume) != isinstance(moving, Volume):
        raise InputError(None, "give both volumes as files or both as Volume objects")
    if isinstance(fixed, Volume):
        names = (fixed.name, moving.name)
    else:
        names = (str(fixed), str(moving))
        fixed, moving = read_volume_pair(fixed, moving)
    result = run_stages(chain_with(["register_3d"], {"register_3d": options}), values={"fixed": fixed, "moving": moving},
                        label=f"{names[0]}|{names[1]}")
    if not result.ok:
        raise StageError(result.error or "registration failed")
    params = Register3DParams.model_validate(options)
    reg = result.final("registration")
    t = reg.transform
    return VolumeRegistrationOutcome(
        fixed=names[0], moving=names[1], dimension=3, convention=CONVENTION_3D,
        parameters=[round(v, 9) for v in t.params], angles=[round(a, 6) for a in t.angles_deg],
        translation=[round(float(v), 6) for v in t.translation], center=[round(float(c), 6) for c in t.center],
        matrix=[[round(float(v), 9) for v in row] for row in t.matrix4()], metric=params.metric.name,
        alpha=params.metric.alpha, method=reg.method, objective=reg.value, iterations=reg.iterations,
        evaluations=reg.evaluations, overlap=round(reg.overlap, 4), seconds=round(reg.seconds, 4), ok=reg.ok,
        reason=reg.reason, registration=reg, fixed_volume=fixed, moving_volume=moving)


def register_with(fixed: Image | Volume | str | Path, moving: Image | Volume | str | Path,
                  overrides: dict[str, dict[str, Any]]) -> RegistrationOutcome | VolumeRegistrationOutcome:
    """:func:`register` with the options as ``{stage: {param: value}}`` (what the CLI collects)."""
    if is_volume_pair(fixed, moving, overrides):
        return register_volumes_with(fixed, moving, overrides)
    in_memory = isinstance(fixed, Image) and isinstance(moving, Image)
    if in_memory:
        if "load_pair" in overrides:
            raise InputError(None, "fixed_slice / moving_slice apply to image files, not to images in memory")
        chain = chain_with(["register"], overrides)
        result = run_stages(chain, values={"fixed": fixed, "moving": moving}, label=f"{fixed.name}|{moving.name}")
        names = (fixed.name, moving.name)
    else:
        if isinstance(fixed, Image) or isinstance(moving, Image):
            raise InputError(None, "give both images as files or both as Image objects")
        chain = chain_with(["load_pair", "register"], overrides)
        result = run_stages(chain, paths={"fixed_path": Path(fixed), "moving_path": Path(moving)},
                            label=f"{fixed}|{moving}")
        names = (str(fixed), str(moving))
    if not result.ok:
        if result.error_stage == "load_pair":
            raise InputError(None, result.error or "cannot read the images")
        raise StageError(result.error or "registration failed")
    params = RegisterParams.model_validate(overrides.get("register", {}))
    reg = result.final("registration")
    t = reg.transform
    return RegistrationOutcome(
        fixed=names[0], moving=names[1], convention=CONVENTION,
        tx=round(t.tx, 6), ty=round(t.ty, 6), angle=round(t.angle, 6), center=[round(c, 3) for c in t.center],
        metric=params.metric.name, alpha=params.metric.alpha, method=reg.method, objective=reg.value,
        iterations=reg.iterations, evaluations=reg.evaluations, seconds=round(reg.seconds, 4), ok=reg.ok,
        reason=reg.reason, registration=reg, fixed_image=result.final("fixed") if not in_memory else fixed,
        moving_image=result.final("moving") if not in_memory else moving)


def _to_uint8(data: np.ndarray, reference: np.ndarray) -> np.ndarray:
    lo, hi = float(reference.min()), float(reference.max())
    if lo >= 0 and hi <= 255 and np.allclose(reference, np.round(reference)):
        return np.clip(np.round(data), 0, 255).astype(np.uint8)
    return np.clip(np.round((data - lo) / (hi - lo) * 255), 0, 255).astype(np.uint8)


def write_registration_files(outcome: RegistrationOutcome, out: str | Path) -> list[str]:
    """The moving image resampled onto the fixed grid (``moving_resampled.png`` 8-bit and ``.tif``
    float32, and in the moving file's own format when it is NIfTI, MetaImage or NRRD, with the fixed
    image's spacing), ``transform.tfm`` (SimpleITK's Euler2DTransform of the result, in the pixel
    coordinates x = (column, row) the registration works in: physical coordinates for images of unit
    spacing and zero origin, such as PNG), ``overlay.png`` and ``registration.json`` (the JSON fields
    and the optimiser's history) in ``out``; returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from PIL import Image as PILImage

    from topomatch.stages.registration.interpolation import resample
    from topomatch.stages.registration.reports import overlay_figure

    out = Path(out)
    fixed, moving, reg = outcome.fixed_image, outcome.moving_image, outcome.registration
    resampled = resample(moving, reg.transform, fixed.shape)
    paths = [out / "moving_resampled.png", out / "moving_resampled.tif", out / "overlay.png", out / "registration.json"]
    buf = io.BytesIO()
    PILImage.fromarray(_to_uint8(resampled, moving.data)).save(buf, format="PNG")
    atomic_write_bytes(paths[0], buf.getvalue())
    buf = io.BytesIO()
    PILImage.fromarray(resampled.astype(np.float32)).save(buf, format="TIFF")
    atomic_write_bytes(paths[1], buf.getvalue())
    fig = overlay_figure(fixed, moving, reg, title=f"{Path(outcome.fixed).name} <- {Path(outcome.moving).name}")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(paths[2], buf.getvalue())
    history = {k: np.asarray(v).tolist() for k, v in reg.history.items()}
    atomic_write_text(paths[3], json.dumps({**outcome.to_dict(), "history": history}, default=str))
    return [str(p) for p in paths] + _write_sitk_files(outcome, resampled, out)


def _write_sitk_files(outcome: RegistrationOutcome, resampled: np.ndarray, out: Path) -> list[str]:
    """``transform.tfm`` and, for a NIfTI / MetaImage / NRRD moving file, ``moving_resampled`` in that format."""
    import math

    import SimpleITK as sitk

    from topomatch.stages.registration.io import NIFTI_SUFFIXES, SITK_SUFFIXES, image_format
    from topomatch.stages.registration.volume_io import keep_locale, output_suffix

    t = outcome.registration.transform
    written = [out / "transform.tfm"]
    tmp = out / ".tmp-transform.tfm"
    sitk.WriteTransform(sitk.Euler2DTransform(tuple(map(float, t.center)), math.radians(t.angle), (t.tx, t.ty)), str(tmp))
    tmp.replace(written[0])
    fmt = image_format(outcome.moving) if Path(outcome.moving).is_file() else ""
    if fmt in NIFTI_SUFFIXES or fmt in SITK_SUFFIXES and fmt not in (".dcm", ".dicom", ".ima"):
        suffix = output_suffix(outcome.moving)
        image = sitk.GetImageFromArray(resampled.astype(np.float32))
        image.SetSpacing(tuple(float(s) for s in reversed(outcome.fixed_image.spacing)))  # (column, row)
        written.append(out / f"moving_resampled{suffix}")
        tmp = out / f".tmp-moving_resampled{suffix}"
        with keep_locale():
            sitk.WriteImage(image, str(tmp), True)
        tmp.replace(written[1])
    return [str(p) for p in written]


def write_volume_registration_files(outcome: VolumeRegistrationOutcome, out: str | Path) -> list[str]:
    """For a 3D registration, in ``out``: the moving volume resampled onto the fixed grid
    (``moving_resampled`` + the moving file's format, ``.nii.gz`` for DICOM or in-memory input; the fixed
    geometry, the moving pixel type), ``transform.tfm`` (ITK transform file: ``sitk.ReadTransform``),
    ``overlay.png`` (three orthogonal slices, checkerboards before / after) and ``registration.json``;
    returns their paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import SimpleITK as sitk

    from topomatch.stages.registration.misalign3d import resample_volume
    from topomatch.stages.registration.reports import volume_overlay_figure
    from topomatch.stages.registration.volume_io import output_suffix, resample_moving, volume_to_sitk, write_transform

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    reg = outcome.registration
    from_files = Path(outcome.fixed).exists() and Path(outcome.moving).exists()
    suffix = output_suffix(outcome.moving) if from_files else ".nii.gz"
    paths = [out / f"moving_resampled{suffix}", out / "transform.tfm", out / "overlay.png", out / "registration.json"]
    if from_files:
        image = resample_moving(outcome.moving, outcome.fixed, reg.transform)
    else:
        moving = outcome.moving_volume
        image = volume_to_sitk(outcome.fixed_volume, resample_volume(moving, reg.transform, outcome.fixed_volume,
                                                                     fill=float(moving.data.min())))
    tmp = paths[0].with_name(f".tmp-{paths[0].name}")
    sitk.WriteImage(image, str(tmp), True)
    tmp.replace(paths[0])
    tmp = paths[1].with_name(".tmp-transform.tfm")
    write_transform(reg.transform, tmp)
    tmp.replace(paths[1])
    fig = volume_overlay_figure(outcome.fixed_volume, outcome.moving_volume, reg,
                                title=f"{Path(outcome.fixed).name} <- {Path(outcome.moving).name}")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    atomic_write_bytes(paths[2], buf.getvalue())
    history = {k: np.asarray(v).tolist() for k, v in reg.history.items()}
    atomic_write_text(paths[3], json.dumps({**outcome.to_dict(), "history": history}, default=str))
    return [str(p) for p in paths]
