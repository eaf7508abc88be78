"""Reading and writing the registration's images, 2D and 3D (the files themselves:
:mod:`topomatch.stages.imaging.files`).

Every reader returns an :class:`Image` in SimpleITK's array order with ITK's geometry as SimpleITK reads it (LPS mm), a
Pillow image with spacing 1 and origin 0. Two axes of more than one pixel make a 2D image, three a volume;
``slice_index`` takes a 2D slice of a volume. Every problem is an :class:`~topomatch.pipeline.errors.InputError` naming
the file (docs/registration.md, "Bad input")."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field

from topomatch.pipeline.contract import InputError, Params, StageResult, stage
from topomatch.stages.imaging.files import file_stem, image_dimension, read_array
from topomatch.stages.registration.image import Image
from topomatch.stages.registration.transform import RigidTransform


def check_pixels(arr: np.ndarray, path: str | Path | None) -> np.ndarray:
    """``arr`` as float64 after the checks every registration input needs (InputError: empty, non-numeric,
    NaN/infinite, beyond 1e100 in magnitude, constant, or fewer than 4 pixels along an axis)."""
    if arr.size == 0 or 0 in arr.shape:
        raise InputError(path, f"image is empty (shape {arr.shape})")
    if not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise InputError(path, f"pixels are not numbers (dtype {arr.dtype})")
    if np.iscomplexobj(arr):
        raise InputError(path, f"pixels are complex numbers (dtype {arr.dtype}); register their magnitude or one part")
    data = np.ascontiguousarray(arr, dtype=np.float64)
    if (bad := ~np.isfinite(data)).any():
        raise InputError(path, f"{int(bad.sum())} of {data.size} pixels are NaN or infinite; mask or fill them first")
    lo, hi = float(data.min()), float(data.max())
    if max(-lo, hi) > 1e100:  # squared and summed over the pixels (moments, variances): 1e302 gave NaN parameters
        raise InputError(path, f"pixel values span {lo:g} to {hi:g}: beyond 1e100 their squares' sums overflow double "
                               f"precision; rescale the image")
    if hi - lo <= 0:
        raise InputError(path, f"image is constant (every pixel is {lo:g}): it has no structure to register")
    if min(data.shape) < 4:
        hint = "; a stack of 2D images: register one slice (--fixed-slice / --moving-slice)" if data.ndim == 3 else ""
        raise InputError(path, f"image is too small to register (shape {data.shape}; at least 4 pixels per axis{hint})")
    return data


def read_image(path: str | Path, *, slice_index: int | None = None, axis: int = 0, strict_slice: bool = True) -> Image:
    """Read a 2D image or a 3D volume (or one 2D slice of a volume) with its physical geometry: a PNG, TIFF, JPEG, BMP,
    NIfTI, MetaImage, NRRD, DICOM file or DICOM series folder (InputError naming the file: module docstring).

    ``slice_index``: for a volume, the 2D slice to take along ``axis`` of its ``(k, j, i)`` array (negative counts from
    the end); for a 2D image an error, unless ``strict_slice`` is False (then ignored: a config's slice applies to its
    volumes, so that one config can mix volumes and PNGs)."""
    path = Path(path)
    arr, spacing, origin, direction = read_array(path)
    source = str(path)
    if arr.ndim == 3 and slice_index is not None:
        n = arr.shape[axis]
        if not -n <= slice_index < n:
            raise InputError(path, f"slice {slice_index} is out of range: the volume has {n} slices along axis "
                                   f"{axis} (0 to {n - 1})")
        arr = np.take(arr, slice_index, axis=axis)
        spacing = tuple(s for a, s in enumerate(spacing) if a != 2 - axis)
        origin, direction = (0.0, 0.0), np.eye(2)
        source = f"slice {slice_index % n} (axis {axis}) of {path}"
    elif arr.ndim == 2 and slice_index is not None and strict_slice:
        raise InputError(path, f"is a 2D image ({arr.shape[0]} rows x {arr.shape[1]} columns): a slice ({slice_index}) "
                               f"applies only to a 3D volume; leave the slice out")
    if arr.ndim not in (2, 3):
        raise InputError(path, f"is a {arr.ndim}D image of shape {arr.shape}" + (" once its axes of one pixel are dropped: "
                         "too small to register" if arr.ndim < 2 else ": only 2D images and 3D volumes can be registered"))
    return Image(check_pixels(arr, path), spacing, origin, direction, file_stem(path), source)


def to_sitk(image: Image, data: np.ndarray | None = None):
    """A float32 SimpleITK image with the image's geometry (and ``data`` instead of its pixels if given)."""
    import SimpleITK as sitk

    out = sitk.GetImageFromArray(np.ascontiguousarray(image.data if data is None else data, dtype=np.float32))
    out.SetSpacing(image.spacing)
    out.SetOrigin(image.origin)
    out.SetDirection(tuple(image.direction.ravel()))
    return out


def write_transform(transform: RigidTransform, path: str | Path) -> None:
    """T as an ITK transform file (``.tfm``/``.txt``, or ``.h5``) readable by ``sitk.ReadTransform``."""
    import SimpleITK as sitk

    sitk.WriteTransform(transform.to_sitk(), str(path))


# --------------------------------------------------------------------------- stages


class LoadImageParams(Params):
    """Parameters of :func:`load_image`."""

    slice: int | None = Field(None, description="2D slice of a 3D volume along `axis` (2D images ignore it)")
    axis: int = Field(0, ge=0, le=2, description="volume axis of `slice` in (k, j, i) = SimpleITK array order")


class LoadPairParams(Params):
    """Parameters of :func:`load_pair`."""

    fixed_slice: int | None = Field(None, description="2D slice of the fixed image if it is a 3D volume")
    moving_slice: int | None = Field(None, description="2D slice of the moving image if it is a 3D volume")
    axis: int = Field(0, ge=0, le=2, description="volume axis of the slices in (k, j, i) = SimpleITK array order")


def _describe(image: Image) -> dict:
    return {"size": "x".join(map(str, image.size)), "spacing": list(image.spacing),
            "min": float(image.data.min()), "max": float(image.data.max())}


@dataclass(frozen=True, eq=False)
class LoadImageResult(StageResult):
    """One image read from a file."""

    image: Image

    def summary(self) -> dict:
        return _describe(self.image)


@dataclass(frozen=True, eq=False)
class LoadPairResult(StageResult):
    """A fixed (reference) and a moving image, both 2D or both 3D."""

    fixed: Image
    moving: Image

    def summary(self) -> dict:
        return {f"{role}_{k}": v for role, im in (("fixed", self.fixed), ("moving", self.moving))
                for k, v in _describe(im).items() if k in ("size", "spacing")}


@stage("load_image", params=LoadImageParams, version=2, consumes=("path",), produces=("image",))
def load_image(path: str, *, params: LoadImageParams) -> LoadImageResult:
    """Read one 2D image or 3D volume (PNG, TIFF, NIfTI, DICOM, MetaImage, NRRD), or one slice of a volume."""
    return LoadImageResult(read_image(path, slice_index=params.slice, axis=params.axis, strict_slice=False))


def read_pair(fixed_path: str | Path, moving_path: str | Path, params: LoadPairParams = LoadPairParams()):
    """Both images, after checking that they have one dimensionality (InputError naming the odd one)."""
    paths = {"fixed": Path(fixed_path), "moving": Path(moving_path)}
    slices = {"fixed": params.fixed_slice, "moving": params.moving_slice}
    dims = {role: 2 if slices[role] is not None else image_dimension(p) for role, p in paths.items()}
    for role in dims:
        if dims[role] not in (2, 3):
            read_image(paths[role])  # the reader's own message (a 4D series, a line of pixels)
    if dims["fixed"] != dims["moving"]:
        role = max(dims, key=dims.get)
        other = "moving" if role == "fixed" else "fixed"
        raise InputError(paths[role], f"the {role} image is {dims[role]}D but the {other} image "
                                      f"{paths[other].name} is {dims[other]}D: images of different dimensionality "
                                      f"cannot be registered; give --{role}-slice (load_pair.{role}_slice in a "
                                      f"config) to take a 2D slice")
    return tuple(read_image(paths[r], slice_index=slices[r], axis=params.axis) for r in ("fixed", "moving"))


@stage("load_pair", params=LoadPairParams, version=2, consumes=("fixed_path", "moving_path"),
       produces=("fixed", "moving"))
def load_pair(fixed_path: str, moving_path: str, *, params: LoadPairParams) -> LoadPairResult:
    """Read a fixed and a moving image: two 2D images (or slices) or two 3D volumes."""
    return LoadPairResult(*read_pair(fixed_path, moving_path, params))


def read_volume(path: str | Path) -> Image:
    """:func:`read_image` of a file that must be a 3D volume (InputError naming it otherwise)."""
    if (image := read_image(path)).dim != 3:
        raise InputError(path, f"is a {image.dim}D image ({' x '.join(map(str, image.size))}); a 3D registration "
                               f"needs volumes (NIfTI, MetaImage, NRRD, DICOM)")
    return image
