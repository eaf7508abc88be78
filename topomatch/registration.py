"""Rigid registration of two images, 2D or 3D: the Python API behind ``topomatch register``.

:func:`register` runs ``load_pair -> register`` (or ``register`` alone on in-memory
:class:`~topomatch.stages.registration.image.Image` objects) through the engine's runner, exactly as
``topomatch register`` and a config do, with the ``register`` stage's defaults for everything not given.
Two 2D images (or slices: ``fixed_slice`` / ``moving_slice``) give the three parameters of SimpleITK's
``Euler2DTransform``, two volumes the six of ``Euler3DTransform``: the same result type,
:class:`RegistrationOutcome`, in physical units (pixels for a PNG, LPS mm for a volume), with
``moving(T(p)) ~ fixed(p)`` for ``T(p) = R (p - c) + c + t``. :func:`write_registration_files` writes what
``--out`` writes.
"""

from __future__ import annotations

import io
import json
import math
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from topomatch.pipeline.cli_options import Option
from topomatch.pipeline.config import chain_with
from topomatch.pipeline.mappings import deep_merge, set_path
from topomatch.pipeline.errors import InputError, StageError
from topomatch.pipeline.files import atomic_write_bytes
from topomatch.pipeline.item import run_stages
from topomatch.stages.registration.image import Image
from topomatch.stages.imaging.files import check_geometry
from topomatch.stages.registration.io import check_pixels
from topomatch.stages.registration.io import read_image as _read_image
from topomatch.stages.registration.io import read_volume  # noqa: F401 (the API)
from topomatch.stages.registration.params import RegisterParams
from topomatch.stages.registration.register import Registration

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

CONVENTION = {
    2: "ITK Euler2DTransform: T(p) = R(angle)(p - c) + c + t, p physical (col, row pixels for PNG), c = centre of "
       "the fixed grid, moving(T(p)) ~ fixed(p); matrix = 3x3 fixed-to-moving map",
    3: "ITK Euler3DTransform: T(p) = R (p - c) + c + t, R = Rz(az) Rx(ax) Ry(ay), p physical LPS mm, c = centre of "
       "the fixed grid, fixed(p) ~ moving(T(p)); matrix = 4x4 fixed-to-moving map",
}


@dataclass(frozen=True, eq=False)
class RegistrationOutcome:
    """The result of one registration, 2D or 3D, with the fields ``topomatch register --json`` prints.

    JSON fields (:meth:`to_dict`): ``fixed``, ``moving`` (names), ``dimension`` (2 or 3), ``convention``,
    ``names`` and ``parameters`` (SimpleITK's order: angles in radians, then the translation), ``angles``
    (degrees), ``translation``, ``center`` (c), ``matrix`` (the homogeneous fixed-to-moving matrix, row-major),
    ``metric``, ``alpha`` (the order used: ``metric.outline_alpha`` on an outline-only, discrete or little-spread pair), ``method``, ``objective`` (the measure at the result), ``iterations``,
    ``evaluations``, ``overlap``, ``seconds``, ``ok`` (the self-check passed), ``reason`` (why not) and
    ``flags`` (the names of the tests that failed); in 2D also ``tx``, ``ty`` and ``angle`` (degrees), the
    names of the previous release. Besides them: ``registration`` (the full
    :class:`~topomatch.stages.registration.register.Registration`, with the optimiser's history),
    ``fixed_image`` and ``moving_image``.
    """

    fixed: str
    moving: str
    registration: Registration = field(repr=False)
    fixed_image: Image = field(repr=False)
    moving_image: Image = field(repr=False)
    metric: str = "jt"
    alpha: float = 2.0

    def __getattr__(self, name: str) -> Any:
        """The JSON fields as attributes (``outcome.tx``, ``outcome.matrix``, ``outcome.ok``)."""
        if name.startswith("_") or "registration" not in self.__dict__:
            raise AttributeError(name)
        fields = self.to_dict()
        if name in fields:
            return fields[name]
        raise AttributeError(f"{type(self).__name__} has no field {name!r}")

    def to_dict(self) -> dict[str, Any]:
        """The JSON fields as a plain dict (strict JSON: a value that is not finite is None)."""
        reg, t = self.registration, self.registration.transform
        out = {"fixed": self.fixed, "moving": self.moving, "dimension": t.dim, "convention": CONVENTION[t.dim],
               "names": list(t.names), "parameters": [json_number(v, 12) for v in t.parameters],
               "angles": [json_number(a) for a in t.angles_deg], "translation": [json_number(v) for v in t.translation],
               "center": [json_number(c) for c in t.center],
               "matrix": [[json_number(v, 12) for v in row] for row in t.matrix()],
               "metric": self.metric, "method": reg.method,  # MI is Shannon's: order 1
               "alpha": 1.0 if self.metric == "mi" else reg.measures.get("outline_alpha", self.alpha),
               "objective": json_number(reg.value, 12), "iterations": reg.iterations, "evaluations": reg.evaluations,
               "overlap": round(reg.overlap, 4), "seconds": round(reg.seconds, 4), "ok": reg.ok, "reason": reg.reason,
               "flags": [f.check for f in reg.flags],
               "measures": {k: json_number(v) for k, v in reg.measures.items()}}
        if t.dim == 2:
            out.update({"tx": json_number(t.tx), "ty": json_number(t.ty), "angle": json_number(t.angle)})
        return out


def json_number(value, digits: int = 10) -> float | None:
    """``value`` to ``digits`` significant digits (a translation in metres keeps its precision as one in
    micrometres does), None when it is not finite (strict JSON has no NaN or infinity)."""
    value = float(value)
    return float(f"{value:.{digits}g}") if math.isfinite(value) else None


def strict_lists(values) -> list:
    """An array as nested lists, full precision, a float that is not finite as None (strict JSON)."""
    a = np.asarray(values)
    return np.where(np.isfinite(a), a, None).tolist() if a.dtype.kind == "f" else a.tolist()


def _input(value: Any, role: str) -> Image | Path:
    """A registration input: an :class:`Image`, whose pixels and geometry get the checks a file's get, or a path;
    InputError naming the role for anything else (an array: wrap it in an Image, with its spacing)."""
    if isinstance(value, Image):
        label = f"the {role} image" + (f" {value.name!r}" if value.name else "")
        check_pixels(value.data, label)
        check_geometry(label, value.spacing, value.origin, value.direction)
        return value
    if isinstance(value, (str, Path)):
        return Path(value)
    hint = (": wrap an array as topomatch.Image(array, spacing=...)" if isinstance(value, np.ndarray) else "")
    raise InputError(None, f"the {role} image must be a file path or an Image, not {type(value).__name__}{hint}")


def read_image(path: str | Path, *, slice: int | None = None) -> Image:
    """A 2D image or 3D volume (PNG, TIFF, NIfTI, DICOM file or series folder, MetaImage, NRRD), or one 2D slice
    of a volume (along its first array axis).

    Raises
    ------
    InputError
        Missing, unreadable or unusable file (names it).
    """
    return _read_image(path, slice_index=slice)


def register(fixed: Image | str | Path, moving: Image | str | Path, *, metric: str | None = None,
             alpha: float | None = None, weights: str | None = None, optimizer: str | None = None,
             seed: int | None = None, fixed_slice: int | None = None, moving_slice: int | None = None,
             params: dict[str, Any] | None = None) -> RegistrationOutcome:
    """Register ``moving`` to ``fixed`` (rigid): two 2D images or two 3D volumes, as files or :class:`Image` s.

    Parameters
    ----------
    fixed, moving : Image or path
    metric : {'jt', 'jr', 'mi', 'tmi'}, optional
        Jensen-Tsallis (the default, thesis ch. 2), Jensen-Renyi, mutual information, Tsallis MI.
    alpha : float, optional
        Entropy order of jt, jr, tmi (default 2).
    weights : {'histogram', 'uniform'}, optional
        Jensen weights (default: the reference histogram).
    optimizer : {'spsa', 'powell'}, optional
        Default SPSA.
    seed : int, optional
        Seed of SPSA and of the sample subsets (the same seed gives the same result).
    fixed_slice, moving_slice : int, optional
        Files only: register this 2D slice of a 3D volume.
    params : dict, optional
        Any other parameter of the registration, nested as ``topomatch stages --json`` lists them, e.g.
        ``{"check": {"min_flatness": 0.2}, "sampling": {"margin": 8}}``: the command line's ``--set check.min_flatness=0.2``.

    Returns
    -------
    RegistrationOutcome
        ``ok`` is False, with a ``reason``, when the self-check flags the result.

    Raises
    ------
    InputError
        An unreadable or unusable image, or images of different dimensionality (names it).
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
            set_path(overrides, REGISTER_OPTIONS[keyword].path, value, keyword)
    if params:
        RegisterParams.parse(params, "params")  # a bad value named as the caller wrote it, before any image is read
        overrides["register"] = deep_merge(params, overrides.get("register", {}))  # a keyword above wins
    return register_with(fixed, moving, overrides)


def register_with(fixed: Image | str | Path, moving: Image | str | Path,
                  overrides: dict[str, dict[str, Any]]) -> RegistrationOutcome:
    """:func:`register` with the options as ``{stage: {param: value}}`` (what the CLI collects)."""
    fixed, moving = _input(fixed, "fixed"), _input(moving, "moving")
    if isinstance(fixed, Image) != isinstance(moving, Image):
        raise InputError(None, "give both images as files or both as Image objects")
    if isinstance(fixed, Image):
        if "load_pair" in overrides:
            raise InputError(None, "fixed_slice / moving_slice apply to image files, not to images in memory")
        result = run_stages(chain_with(["register"], overrides), values={"fixed": fixed, "moving": moving},
                            label=f"{fixed.name}|{moving.name}")
        names = (fixed.name, moving.name)
    else:
        result = run_stages(chain_with(["load_pair", "register"], overrides),
                            paths={"fixed_path": fixed, "moving_path": moving}, label=f"{fixed}|{moving}")
        names = (str(fixed), str(moving))
    if not result.ok:
        if result.error_stage == "load_pair":
            raise InputError(None, result.error or "cannot read the images")
        raise StageError(result.error or "registration failed")
    metric = RegisterParams.parse(overrides.get("register", {}), "register").metric
    return RegistrationOutcome(names[0], names[1], result.final("registration"),
                               result.final("fixed") if not isinstance(fixed, Image) else fixed,
                               result.final("moving") if not isinstance(moving, Image) else moving,
                               metric.name, metric.alpha)


def _png_pixels(data: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``data`` as a PNG stores it: the moving image's own values when they are integers that 8 or 16 bits hold (a
    16-bit PNG stays 16-bit), else scaled to 8 bits over the moving image's range."""
    lo, hi = float(reference.min()), float(reference.max())
    if lo >= 0 and hi <= 65535 and np.allclose(reference, np.round(reference)):
        dtype, top = (np.uint8, 255) if hi <= 255 else (np.uint16, 65535)
        return np.clip(np.round(data), 0, top).astype(dtype)
    return np.clip(np.round((data - lo) / (hi - lo) * 255), 0, 255).astype(np.uint8)


def _stored_pixel_id(path: Path):
    """The pixel type of a SimpleITK-readable file (None for Pillow formats, folders and slices' volumes)."""
    import SimpleITK as sitk

    from topomatch.stages.imaging.files import PILLOW_SUFFIXES, image_format

    if not path.is_file() or image_format(path) in PILLOW_SUFFIXES:
        return None
    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    reader.ReadImageInformation()
    return reader.GetPixelID()


#: What ``write_registration_files`` writes into its folder (the resampled moving image: ``moving_resampled.*``).
OUTPUT_NAMES = ("overlay.png", "registration.json", "transform.tfm")
OVERLAY_PIXELS = 1024
"""The overlay figure draws each image block-averaged to at most this many pixels an axis (its panels are ~350 px
wide): on a 3,000-pixel section (a hostile user's pass) --out took 18.5 s and 1.79 GB drawing it at full resolution,
12.3 s and 0.71 GB so, most of the rest writing the 9-megapixel resampled image."""


def check_outputs_spare_inputs(out: str | Path, *inputs: str | Path) -> None:
    """Refuse an output folder where writing the registration's files would replace one of its inputs (before the
    registration runs, so that nothing is computed for nothing)."""
    folder = Path(out).resolve()
    for p in inputs:
        p = Path(p).resolve()
        if p.parent == folder and (p.name in OUTPUT_NAMES or p.name.startswith("moving_resampled.")):
            raise InputError(p, "is one of the registration's input files: writing --out there would replace it; "
                                "choose another --out folder")


def write_registration_files(outcome: RegistrationOutcome, out: str | Path) -> list[str]:
    """In ``out``: the moving image resampled onto the fixed grid, in the moving file's format
    (``moving_resampled`` + ``.png`` 8-bit, or 16-bit for a 16-bit moving image, for Pillow formats, with a float32 ``.tif`` beside it; the file's own
    format with the fixed geometry and the moving pixel type for NIfTI / MetaImage / NRRD; ``.nii.gz`` for
    DICOM or in-memory images), ``transform.tfm`` (SimpleITK's Euler2D / Euler3D transform of the result:
    ``sitk.ReadTransform`` reads it, ``sitk.Resample(moving, fixed, T, sitk.sitkLinear, moving_minimum)`` gives the
    resampling: outside the moving field of view the moving image's minimum, not SimpleITK's default 0),
    ``overlay.png`` (fixed, moving, checkerboards before / after, colour overlay; three orthogonal planes for a
    volume; at most :data:`OVERLAY_PIXELS` an axis) and ``registration.json`` (the JSON fields and the optimiser's history); returns their paths. A file that
    cannot be written does not stop the others: the first such OSError is raised once all were tried, its
    ``written`` attribute listing the paths that were."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import SimpleITK as sitk

    from topomatch.stages.imaging.files import keep_locale, output_suffix
    from topomatch.stages.registration.io import to_sitk, write_transform
    from topomatch.stages.registration.reports import overlay_figure

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fixed, moving, reg = outcome.fixed_image, outcome.moving_image, outcome.registration
    resampled = sitk.GetArrayFromImage(sitk.Resample(to_sitk(moving), to_sitk(fixed), reg.transform.to_sitk(),
                                                     sitk.sitkLinear, float(moving.data.min()), sitk.sitkFloat64))
    moving_path = Path(outcome.moving)
    from_file = moving_path.exists() and "slice" not in moving.source  # the whole file, not a slice or in memory
    suffix = output_suffix(moving_path) if from_file else ".nii.gz"
    written: list[Path] = []
    failures: list[OSError] = []

    inputs = {Path(p).resolve() for p in (outcome.fixed, outcome.moving) if isinstance(p, (str, Path))}

    def save(path: Path, data: bytes | None = None, write=None) -> None:
        if path.resolve() in inputs:  # --out next to the inputs: never write over one of them
            raise InputError(path, "is one of the registration's input files: choose another --out folder")
        try:
            if write is not None:  # a writer that takes a path (SimpleITK): its bytes, then written as the others are
                with tempfile.TemporaryDirectory() as scratch:
                    write(Path(scratch) / path.name)
                    data = (Path(scratch) / path.name).read_bytes()
            atomic_write_bytes(path, data)
            written.append(path)
        except OSError as exc:  # the other files are still written; the first failure is raised at the end
            failures.append(exc)

    if suffix == ".png":
        from PIL import Image as PILImage

        for name, array, fmt in (("moving_resampled.png", _png_pixels(resampled, moving.data), "PNG"),
                                 ("moving_resampled.tif", resampled.astype(np.float32), "TIFF")):
            buf = io.BytesIO()
            PILImage.fromarray(array).save(buf, format=fmt)
            save(out / name, buf.getvalue())
    else:
        image = to_sitk(fixed, resampled)
        pixel = _stored_pixel_id(moving_path) if from_file else None
        if pixel is not None and pixel != image.GetPixelID():
            image = sitk.Cast(sitk.Round(image) if pixel not in (sitk.sitkFloat32, sitk.sitkFloat64) else image, pixel)

        def write_image(tmp: Path) -> None:
            with keep_locale():
                sitk.WriteImage(image, str(tmp), True)

        save(out / f"moving_resampled{suffix}", write=write_image)
    save(out / "transform.tfm", write=lambda tmp: write_transform(reg.transform, tmp))
    shown = [image.shrink([-(-n // OVERLAY_PIXELS) for n in image.size]) for image in (fixed, moving)]
    fig = overlay_figure([(*shown, reg, f"{Path(outcome.fixed).name} <- {moving_path.name}")],
                         top=0.9 if fixed.dim == 2 else 0.95, bottom=0.12 if fixed.dim == 2 else 0.02, hspace=0.25)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100 if fixed.dim == 3 else 110, bbox_inches="tight")
    plt.close(fig)
    save(out / "overlay.png", buf.getvalue())
    history = {k: strict_lists(v) for k, v in reg.history.items()}
    save(out / "registration.json", json.dumps({**outcome.to_dict(), "history": history}, default=str).encode())
    stale = sorted(set(out.glob("moving_resampled.*")) - set(written))  # an earlier run's, in another format
    if stale:
        warnings.warn(f"{out}: {', '.join(p.name for p in stale)} from an earlier run stay beside this run's files (this "
                      f"run wrote {', '.join(p.name for p in written if p.name.startswith('moving_resampled'))}); remove "
                      f"them or write to another --out folder", stacklevel=2)
    if failures:
        failures[0].written = [str(p) for p in written]  # what the caller can still list (the CLI's ``files``)
        raise failures[0]
    return [str(p) for p in written]
