"""Reading and writing 3D volumes through SimpleITK (the adapter between SimpleITK images and
:class:`~topomatch.stages.registration.volume.Volume`).

Formats: NIfTI (``.nii``, ``.nii.gz``), MetaImage (``.mha``, ``.mhd``), NRRD (``.nrrd``, ``.nhdr``),
a single-file DICOM volume, or a folder holding one DICOM series. Spacing, origin and direction are
SimpleITK's (LPS millimetres; a NIfTI's qform/sform is converted by SimpleITK), so physical points,
transforms and matrices here agree with SimpleITK's, elastix's and ANTs' readings of the same files.

Every problem is an :class:`~topomatch.pipeline.errors.InputError` naming the file or folder:
missing or unreadable input, a folder with no DICOM series or several (mixed series), a 2D image, a
4D (time series) or vector-valued volume, more voxels than the size limit, NaN or infinite voxels,
a constant volume, fewer than 4 voxels along an axis, and in :func:`load_volume_pair` inputs of
different dimensionality.
"""

from __future__ import annotations

import contextlib
import locale
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from topomatch.pipeline.contract import InputError, Params, StageResult, stage
from topomatch.stages.registration.io import PILLOW_SUFFIXES, _check_size, _stem, check_pixels, image_format
from topomatch.stages.registration.transform3d import RigidTransform3D
from topomatch.stages.registration.volume import Volume

VOLUME_SUFFIXES = (".nii", ".nii.gz", ".mha", ".mhd", ".nrrd", ".nhdr", ".dcm", ".dicom", ".ima")


def _sitk_detail(exc: Exception) -> str:
    lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "SimpleITK could not read it"


@contextlib.contextmanager
def keep_locale():
    """Restore the process locale afterwards: ITK's GDCM calls can set it to "C" and leave it there (Python's
    default text encoding then becomes ASCII for the rest of the process)."""
    saved = locale.setlocale(locale.LC_ALL)
    try:
        yield
    finally:
        try:
            locale.setlocale(locale.LC_ALL, saved)
        except locale.Error:  # a composite setting this platform cannot restore in one call
            pass


def _dicom_files(folder: Path) -> list[str]:
    """The file names of the one DICOM series in ``folder`` (InputError for none or several)."""
    import SimpleITK as sitk

    ids = sitk.ImageSeriesReader.GetGDCMSeriesIDs(str(folder))
    if not ids:
        raise InputError(folder, "is a folder without a DICOM series; give a DICOM series folder or a volume file "
                                 "(.nii, .nii.gz, .mha, .mhd, .nrrd)")
    if len(ids) > 1:
        counts = [f"{sid} ({len(sitk.ImageSeriesReader.GetGDCMSeriesFileNames(str(folder), sid))} files)"
                  for sid in ids]
        raise InputError(folder, f"holds {len(ids)} DICOM series ({'; '.join(counts)}); a registration input is one "
                                 f"series: put each series in its own folder")
    return list(sitk.ImageSeriesReader.GetGDCMSeriesFileNames(str(folder), ids[0]))


def image_dimension(path: str | Path) -> int:
    """How many axes of more than one voxel the image at ``path`` has (from its header), 3 for a DICOM
    series folder; 2 for the 2D-only formats (PNG, TIFF, JPEG, BMP). InputError if unreadable."""
    import SimpleITK as sitk

    path = Path(path)
    if path.is_dir():
        return 3
    if not path.exists():
        raise InputError(path, "file not found")
    if image_format(path) in PILLOW_SUFFIXES:
        return 2
    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    try:
        reader.ReadImageInformation()
    except RuntimeError as exc:
        raise InputError(path, f"cannot read image ({_sitk_detail(exc)})") from None
    return sum(1 for s in reader.GetSize() if s > 1)


def read_sitk_volume(path: str | Path):
    """The SimpleITK image of a volume file or DICOM series folder (3D, scalar), as stored."""
    import SimpleITK as sitk

    path = Path(path)
    try:
        if path.is_dir():
            with keep_locale():
                files = _dicom_files(path)
                reader = sitk.ImageFileReader()
                reader.SetFileName(files[0])
                reader.ReadImageInformation()
                _check_size(path, tuple(reader.GetSize()[:2]) + (len(files),))
                image = sitk.ReadImage(files)
        else:
            if not path.exists():
                raise InputError(path, "file not found")
            if not path.is_file():
                raise InputError(path, "not a regular file")
            if path.stat().st_size == 0:
                raise InputError(path, "file is empty (0 bytes)")
            fmt = image_format(path)
            if fmt in PILLOW_SUFFIXES:
                raise InputError(path, f"is a 2D image format ({fmt}); a 3D registration needs volumes (NIfTI, "
                                       f"MetaImage, NRRD, DICOM)")
            reader = sitk.ImageFileReader()
            reader.SetFileName(str(path))
            reader.ReadImageInformation()
            _check_size(path, tuple(reader.GetSize()) + ((reader.GetNumberOfComponents(),)
                                                         if reader.GetNumberOfComponents() > 1 else ()))
            image = reader.Execute()
    except RuntimeError as exc:
        raise InputError(path, f"cannot read volume ({_sitk_detail(exc)})") from None
    size = image.GetSize()
    if image.GetNumberOfComponentsPerPixel() > 1:
        raise InputError(path, f"has {image.GetNumberOfComponentsPerPixel()} components per voxel (colour or vector "
                               f"data); registration needs one intensity per voxel")
    if image.GetDimension() == 4:
        if size[3] == 1:
            image = sitk.Extract(image, list(size[:3]) + [0], [0, 0, 0, 0])
        else:
            raise InputError(path, f"is a 4D image ({' x '.join(map(str, size))}: {size[3]} volumes, e.g. a time "
                                   f"series); extract one 3D volume first (e.g. sitk.Extract or fslroi)")
    if image.GetDimension() != 3 or min(image.GetSize()) < 2:
        raise InputError(path, f"is a {'x'.join(map(str, image.GetSize()))} image, not a 3D volume; register 2D "
                               f"images with 2D images")
    return image


def volume_from_sitk(image, path: str | Path | None = None, name: str = "") -> Volume:
    """A :class:`Volume` (float64) of a 3D scalar SimpleITK image, its voxels checked (:func:`check_pixels`)."""
    import SimpleITK as sitk

    data = check_pixels(sitk.GetArrayFromImage(image), path)
    return Volume(data, image.GetSpacing(), image.GetOrigin(), np.array(image.GetDirection()).reshape(3, 3), name,
                  str(path or ""))


def volume_to_sitk(volume: Volume, data: np.ndarray | None = None):
    """A float32 SimpleITK image with the volume's geometry (and ``data`` instead of its voxels if given)."""
    import SimpleITK as sitk

    out = sitk.GetImageFromArray(np.ascontiguousarray(volume.data if data is None else data, dtype=np.float32))
    out.SetSpacing(volume.spacing)
    out.SetOrigin(volume.origin)
    out.SetDirection(tuple(volume.direction.ravel()))
    return out


def _name(path: Path) -> str:
    return path.name if path.is_dir() else _stem(path)


def read_volume(path: str | Path) -> Volume:
    """Read a 3D volume (NIfTI, MetaImage, NRRD, DICOM file or series folder) with its physical geometry.

    Raises
    ------
    InputError
        See the module docstring; the message names the file.
    """
    path = Path(path)
    return volume_from_sitk(read_sitk_volume(path), path, _name(path))


def write_transform(transform: RigidTransform3D, path: str | Path) -> None:
    """Write T as an ITK transform file (``.tfm``/``.txt``, or ``.h5``) readable by ``sitk.ReadTransform``."""
    import SimpleITK as sitk

    sitk.WriteTransform(transform.to_sitk(), str(path))


def output_suffix(path: str | Path) -> str:
    """The suffix of a volume written "in the input's format": the file's own, ``.nii.gz`` for DICOM input."""
    path = Path(path)
    if path.is_dir():
        return ".nii.gz"
    fmt = image_format(path)
    return {".mhd": ".mha", ".nhdr": ".nrrd", ".dcm": ".nii.gz", ".dicom": ".nii.gz", ".ima": ".nii.gz"}.get(fmt, fmt)


def resample_moving(moving_path: str | Path, fixed_path: str | Path, transform: RigidTransform3D,
                    fill: float | None = None):
    """The moving volume (as stored, its own pixel type) resampled onto the fixed grid by ``moving(T(p))``
    with SimpleITK (linear), as a SimpleITK image with the fixed volume's geometry."""
    import SimpleITK as sitk

    moving, fixed = read_sitk_volume(moving_path), read_sitk_volume(fixed_path)
    if fill is None:
        fill = float(sitk.GetArrayViewFromImage(moving).min())
    return sitk.Resample(moving, fixed, transform.to_sitk(), sitk.sitkLinear, fill, moving.GetPixelID())


# --------------------------------------------------------------------------- stages


class LoadVolumeParams(Params):
    """Parameters of :func:`load_volume` (none: the geometry comes from the file)."""


@dataclass(frozen=True, eq=False)
class LoadVolumeResult(StageResult):
    """One volume read from a file."""

    volume: Volume

    def summary(self) -> dict:
        return {"size": "x".join(map(str, self.volume.size)), "spacing": list(self.volume.spacing)}


@stage("load_volume", params=LoadVolumeParams, version=1, consumes=("path",), produces=("volume",))
def load_volume(path: str, *, params: LoadVolumeParams) -> LoadVolumeResult:
    """Read one 3D volume (NIfTI, MetaImage, NRRD, DICOM) with its physical geometry."""
    return LoadVolumeResult(read_volume(path))


class LoadVolumePairParams(Params):
    """Parameters of :func:`load_volume_pair` (none: the geometry comes from the files)."""


@dataclass(frozen=True, eq=False)
class LoadVolumePairResult(StageResult):
    """A fixed and a moving volume."""

    fixed: Volume
    moving: Volume

    def summary(self) -> dict:
        return {"fixed_size": "x".join(map(str, self.fixed.size)), "moving_size": "x".join(map(str, self.moving.size)),
                "fixed_spacing": list(self.fixed.spacing), "moving_spacing": list(self.moving.spacing)}


def read_volume_pair(fixed_path: str | Path, moving_path: str | Path) -> tuple[Volume, Volume]:
    """Both volumes, after checking that both inputs are 3D (InputError naming the odd one otherwise)."""
    fixed_path, moving_path = Path(fixed_path), Path(moving_path)
    dims = {p: image_dimension(p) for p in (fixed_path, moving_path)}
    for role, p, other in (("fixed", fixed_path, moving_path), ("moving", moving_path, fixed_path)):
        if dims[p] < 3 <= dims[other]:  # a 4D input gets the reader's own message
            raise InputError(p, f"the {role} image is {dims[p]}D but the other input {other.name} is a 3D volume: "
                                f"images of different dimensionality cannot be registered")
    return read_volume(fixed_path), read_volume(moving_path)


@stage("load_volume_pair", params=LoadVolumePairParams, version=1, consumes=("fixed_path", "moving_path"),
       produces=("fixed", "moving"))
def load_volume_pair(fixed_path: str, moving_path: str, *, params: LoadVolumePairParams) -> LoadVolumePairResult:
    """Read a fixed and a moving 3D volume (NIfTI, MetaImage, NRRD, DICOM) with their physical geometry."""
    return LoadVolumePairResult(*read_volume_pair(fixed_path, moving_path))
