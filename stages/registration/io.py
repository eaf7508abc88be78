"""Reading 2D images: PNG/TIFF/JPEG/BMP (Pillow), NIfTI (nibabel), DICOM/MetaImage/NRRD (SimpleITK).

Every reader returns the same thing: a float64 array indexed ``[row, col]`` and the pixel
spacing ``(row, col)`` (1 for PNG/TIFF/JPEG/BMP, whose dpi is a print resolution). Arrays
follow SimpleITK's index order, so a NIfTI file read here equals
``sitk.GetArrayFromImage(sitk.ReadImage(path))`` (nibabel's ``(i, j, k)`` data is transposed
to ``(k, j, i)``). A volume is reduced to 2D by ``slice_index`` along ``axis`` of
that ``(k, j, i)`` array (axis 0 = slices); singleton axes are dropped. Colour images become
their luminance ``0.299 R + 0.587 G + 0.114 B`` (alpha dropped).

Every problem is an :class:`~topomatch.pipeline.errors.InputError` naming the file: missing or
unreadable file, unknown format, a 3D volume without a slice, an empty image, NaN or infinite
pixels, a constant image (nothing to register), and in :func:`load_pair` a fixed and a moving
image of different dimensionality.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field
from topomatch.pipeline.contract import (
    InputError,
    Params,
    StageResult,
    check_readable_file,
    limit_from_env,
    stage,
)
from topomatch.stages.registration.image import Image

PILLOW_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
NIFTI_SUFFIXES = (".nii", ".nii.gz")
SITK_SUFFIXES = (".dcm", ".dicom", ".ima", ".mha", ".mhd", ".nrrd", ".nhdr")
SUPPORTED = PILLOW_SUFFIXES + NIFTI_SUFFIXES + SITK_SUFFIXES


#: Most pixels (or voxels) an image may hold, checked from the file's header before its pixels are
#: decoded, so that a small file cannot claim gigabytes; ``$TOPOMATCH_MAX_IMAGE_PIXELS`` overrides it.
MAX_PIXELS = 100_000_000


def max_pixels() -> int:
    return limit_from_env("TOPOMATCH_MAX_IMAGE_PIXELS", MAX_PIXELS)


def _check_size(path: Path, shape: tuple[int, ...]) -> None:
    """Refuse an image whose header declares more than :func:`max_pixels` pixels."""
    n, limit = math.prod(int(s) for s in shape), max_pixels()
    if n > limit:
        raise InputError(path, f"the header declares {' x '.join(str(int(s)) for s in shape)} = {n:,} pixels, "
                               f"above the limit of {limit:,} (set TOPOMATCH_MAX_IMAGE_PIXELS to raise it)")


def image_format(path: str | Path) -> str:
    """The format suffix of ``path`` (``'.png'``, ``'.nii.gz'``, ...); InputError if unsupported."""
    name = Path(path).name.lower()
    for suffix in sorted(SUPPORTED, key=len, reverse=True):
        if name.endswith(suffix):
            return suffix
    raise InputError(path, f"unsupported image format {Path(path).suffix or '(no suffix)'!r}; expected one of "
                           f"{', '.join(SUPPORTED)}")


def _stem(path: Path) -> str:
    name = path.name
    fmt = image_format(path)
    return name[: -len(fmt)] if name.lower().endswith(fmt) else path.stem


def _read_pillow(path: Path) -> tuple[np.ndarray, tuple[float, ...]]:
    from PIL import Image as PILImage
    from PIL import UnidentifiedImageError

    PILImage.MAX_IMAGE_PIXELS = max_pixels()  # Pillow's own bomb check never fires before ours
    try:
        with PILImage.open(path) as im:
            _check_size(path, (im.size[1], im.size[0]))
            im.load()
            frames = getattr(im, "n_frames", 1)
            if frames > 1:
                raise InputError(path, f"multi-page image with {frames} pages; registration reads single 2D images")
            if im.mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif im.mode in ("LA", "PA"):
                im = im.convert("L")
            elif im.mode == "CMYK":
                im = im.convert("RGB")
            arr = np.asarray(im)
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise InputError(path, f"cannot read image ({type(exc).__name__}: {exc})") from None
    return arr, (1.0, 1.0)  # print resolution (dpi) is not a pixel spacing


def _read_nifti(path: Path) -> tuple[np.ndarray, tuple[float, ...]]:
    import nibabel as nib

    try:
        img = nib.load(str(path))
    except Exception as exc:  # nibabel raises many types for a corrupt file
        raise InputError(path, f"cannot read NIfTI file ({type(exc).__name__}: {exc})") from None
    _check_size(path, img.shape)
    try:
        data = np.asarray(img.dataobj)
        zooms = tuple(float(z) for z in img.header.get_zooms())
    except Exception as exc:  # nibabel raises many types for a corrupt file
        raise InputError(path, f"cannot read NIfTI file ({type(exc).__name__}: {exc})") from None
    while data.ndim > 3 and data.shape[-1] == 1:  # drop trailing singleton time/vector axes
        data = data[..., 0]
    # nibabel: data[i, j, k] with i = x; SimpleITK's array is [k, j, i]: transpose to match it
    data = data.T
    zooms = tuple(reversed(zooms[: data.ndim]))
    return data, zooms


def _read_sitk(path: Path) -> tuple[np.ndarray, tuple[float, ...]]:
    import SimpleITK as sitk

    try:
        reader = sitk.ImageFileReader()
        reader.SetFileName(str(path))
        reader.ReadImageInformation()
        _check_size(path, tuple(reader.GetSize()) + ((reader.GetNumberOfComponents(),)
                                                     if reader.GetNumberOfComponents() > 1 else ()))
        img = reader.Execute()
    except RuntimeError as exc:
        detail = str(exc).strip().splitlines()[-1] if str(exc).strip() else "SimpleITK could not read it"
        raise InputError(path, f"cannot read image ({detail})") from None
    return sitk.GetArrayFromImage(img), tuple(reversed(img.GetSpacing()))


def _to_grey(arr: np.ndarray) -> np.ndarray:
    """Luminance of an RGB(A) array (last axis of length 3 or 4 on a 2D image); others unchanged."""
    if arr.ndim == 3 and arr.shape[-1] in (3, 4) and arr.shape[0] > 4 and arr.shape[1] > 4:
        rgb = arr[..., :3].astype(np.float64)
        return rgb @ np.array([0.299, 0.587, 0.114])
    return arr


def read_array(path: str | Path) -> tuple[np.ndarray, tuple[float, ...]]:
    """The raw pixel array of an image file (grey, singleton axes dropped) and its spacing.

    2D images give ``(H, W)``, volumes ``(k, j, i)`` (SimpleITK order); spacing has one entry
    per axis. Raises :class:`InputError` for a missing, unreadable or unsupported file.
    """
    path = check_readable_file(path)
    if path.stat().st_size == 0:
        raise InputError(path, "file is empty (0 bytes)")
    fmt = image_format(path)
    if fmt in PILLOW_SUFFIXES:
        try:
            arr, spacing = _read_pillow(path)
        except InputError:
            if fmt not in (".tif", ".tiff"):
                raise
            arr, spacing = _read_sitk(path)  # TIFF variants Pillow cannot decode
    elif fmt in NIFTI_SUFFIXES:
        arr, spacing = _read_nifti(path)
    else:
        arr, spacing = _read_sitk(path)
    arr = _to_grey(np.asarray(arr))
    spacing = tuple(float(s) for s in spacing)
    if len(spacing) != arr.ndim:
        spacing = (1.0,) * arr.ndim
    if arr.ndim >= 3 and 1 in arr.shape:
        keep = [a for a in range(arr.ndim) if arr.shape[a] != 1]
        spacing = tuple(spacing[a] for a in keep)
        arr = arr.reshape([arr.shape[a] for a in keep])
    return arr, spacing


def read_image(path: str | Path, *, slice_index: int | None = None, axis: int = 0,
               strict_slice: bool = True) -> Image:
    """Read a 2D image (or one slice of a volume) as float64 ``[row, col]`` with its spacing.

    Parameters
    ----------
    path : str or Path
        PNG, TIFF, JPEG, BMP, NIfTI (``.nii``, ``.nii.gz``), DICOM (``.dcm``), MetaImage
        (``.mha``, ``.mhd``) or NRRD file.
    slice_index : int, optional
        For a 3D volume: the slice to take along ``axis`` (negative counts from the end).
        For a 2D image an error, unless ``strict_slice`` is False (then ignored: the
        ``load_image`` stage, so that one config can mix slices and PNGs).
    axis : {0, 1, 2}
        Axis of the volume's ``(k, j, i)`` array (SimpleITK order) that ``slice_index`` indexes.

    Returns
    -------
    Image
        ``data`` (H, W) float64, ``spacing`` (row, col).

    Raises
    ------
    InputError
        Missing, unreadable or unsupported file; a volume without ``slice_index`` or an index out
        of range; an empty, non-finite or constant image.
    """
    path = Path(path)
    arr, spacing = read_array(path)
    return _image_from_array(path, arr, spacing, slice_index, axis, strict_slice)


def _image_from_array(path: Path, arr: np.ndarray, spacing: tuple[float, ...], slice_index: int | None,
                      axis: int, strict_slice: bool = True) -> Image:
    source = str(path)
    if arr.ndim == 3:
        if slice_index is None:
            raise InputError(path, f"is a 3D volume of shape {arr.shape} (slices, rows, cols); registration is 2D: "
                                   f"choose a slice (--fixed-slice / --moving-slice; in a config load_image.slice, "
                                   f"load_pair.fixed_slice / moving_slice)")
        n = arr.shape[axis]
        if not -n <= slice_index < n:
            raise InputError(path, f"slice {slice_index} is out of range: the volume has {n} slices along axis "
                                   f"{axis} (0 to {n - 1})")
        arr = np.take(arr, slice_index, axis=axis)
        spacing = tuple(s for a, s in enumerate(spacing) if a != axis)
        source = f"slice {slice_index % n} (axis {axis}) of {path}"
    elif arr.ndim == 2 and slice_index is not None and strict_slice:
        raise InputError(path, f"is a 2D image ({arr.shape[0]} x {arr.shape[1]} pixels): a slice ({slice_index}) "
                               f"applies only to a 3D volume; leave the slice out")
    if arr.ndim != 2:
        raise InputError(path, f"is a {arr.ndim}D image of shape {arr.shape}: only 2D images and slices of 3D "
                               f"volumes can be registered")
    data = check_pixels(arr, path)
    return Image(data, (spacing[0], spacing[1]), _stem(path), source)


def check_pixels(arr: np.ndarray, path: str | Path | None) -> np.ndarray:
    """``arr`` as float64 after the checks every registration input needs.

    Raises
    ------
    InputError
        Empty, non-numeric, NaN/infinite, or constant (zero intensity range) pixels.
    """
    if arr.size == 0 or 0 in arr.shape:
        raise InputError(path, f"image is empty (shape {arr.shape})")
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise InputError(path, f"pixels are not numbers (dtype {arr.dtype})")
    data = np.ascontiguousarray(arr, dtype=np.float64)
    bad = ~np.isfinite(data)
    if bad.any():
        raise InputError(path, f"{int(bad.sum())} of {data.size} pixels are NaN or infinite; mask or fill them first")
    lo, hi = float(data.min()), float(data.max())
    if hi - lo <= 0:
        raise InputError(path, f"image is constant (every pixel is {lo:g}): it has no structure to register")
    if min(data.shape) < 4:
        raise InputError(path, f"image is too small to register (shape {data.shape}; at least 4 x 4)")
    return data


# --------------------------------------------------------------------------- stages


class LoadImageParams(Params):
    """Parameters of :func:`load_image`."""

    slice: int | None = Field(None, description="slice of a 3D volume along `axis` (2D images ignore it)")
    axis: int = Field(0, ge=0, le=2, description="volume axis of `slice` in (k, j, i) = SimpleITK array order")


class LoadPairParams(Params):
    """Parameters of :func:`load_pair`."""

    fixed_slice: int | None = Field(None, description="slice of the fixed image if it is a 3D volume")
    moving_slice: int | None = Field(None, description="slice of the moving image if it is a 3D volume")
    axis: int = Field(0, ge=0, le=2, description="volume axis of the slices in (k, j, i) = SimpleITK array order")


@dataclass(frozen=True, eq=False)
class LoadImageResult(StageResult):
    """One image read from a file."""

    image: Image

    def summary(self) -> dict:
        H, W = self.image.shape
        return {"rows": H, "cols": W, "spacing_row": self.image.spacing[0], "spacing_col": self.image.spacing[1],
                "min": float(self.image.data.min()), "max": float(self.image.data.max())}


@dataclass(frozen=True, eq=False)
class LoadPairResult(StageResult):
    """A fixed (reference) and a moving (target) image."""

    fixed: Image
    moving: Image

    def summary(self) -> dict:
        return {"fixed_shape": "x".join(map(str, self.fixed.shape)), "moving_shape": "x".join(map(str, self.moving.shape)),
                "fixed_spacing": list(self.fixed.spacing), "moving_spacing": list(self.moving.spacing)}


@stage("load_image", params=LoadImageParams, version=1, consumes=("path",), produces=("image",))
def load_image(path: str, *, params: LoadImageParams) -> LoadImageResult:
    """Read one 2D image (PNG, TIFF, NIfTI, DICOM, MetaImage), or one slice of a volume."""
    # a config's slice applies to its volumes; its 2D images are read whole (inputs may mix both)
    return LoadImageResult(read_image(path, slice_index=params.slice, axis=params.axis, strict_slice=False))


@stage("load_pair", params=LoadPairParams, version=1, consumes=("fixed_path", "moving_path"),
       produces=("fixed", "moving"))
def load_pair(fixed_path: str, moving_path: str, *, params: LoadPairParams) -> LoadPairResult:
    """Read a fixed and a moving image; both must be 2D (or reduced to 2D by a slice)."""
    fixed_path, moving_path = Path(fixed_path), Path(moving_path)
    (fa, fs), (ma, ms) = read_array(fixed_path), read_array(moving_path)
    dims = {fixed_path: (fa.ndim, params.fixed_slice), moving_path: (ma.ndim, params.moving_slice)}
    if fa.ndim != ma.ndim and params.fixed_slice is None and params.moving_slice is None:
        vol, flat = (moving_path, fixed_path) if ma.ndim > fa.ndim else (fixed_path, moving_path)
        role = "moving" if vol == moving_path else "fixed"
        raise InputError(vol, f"the {role} image is {dims[vol][0]}D ({'x'.join(map(str, (ma if vol == moving_path else fa).shape))}) "
                              f"but the {'fixed' if role == 'moving' else 'moving'} image {flat.name} is "
                              f"{dims[flat][0]}D: images of different dimensionality cannot be registered; "
                              f"give --{role}-slice (load_pair.{role}_slice in a config) to take a 2D slice")
    fixed = _image_from_array(fixed_path, fa, fs, params.fixed_slice, params.axis)
    moving = _image_from_array(moving_path, ma, ms, params.moving_slice, params.axis)
    return LoadPairResult(fixed, moving)
