"""Image files, 2D and 3D, read into arrays with ITK's geometry and checked before they are decoded:
PNG/TIFF/JPEG/BMP (Pillow); NIfTI (nibabel's voxels, SimpleITK's reading of the header); MetaImage, NRRD, DICOM
files and series folders (SimpleITK).

:func:`read_array` returns the pixels in SimpleITK's array order with ITK's geometry as SimpleITK reads it (LPS
mm), a Pillow image with spacing 1 and origin 0; axes of one pixel are dropped. What the headers declare (sizes,
spacings, orientations, data offsets, data files, a DICOM series' slice positions) is checked before ITK or
nibabel parse or allocate it (docs/hardening.md). Every problem is an
:class:`~topomatch.pipeline.errors.InputError` naming the file.
"""

from __future__ import annotations

import contextlib
import locale
from io import BytesIO
import math
import warnings
from pathlib import Path

import numpy as np

from topomatch.pipeline.contract import InputError, InputWarning, check_readable_file, limit_from_env

PILLOW_SUFFIXES = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
SITK_SUFFIXES = (".nii", ".nii.gz", ".dcm", ".dicom", ".ima", ".mha", ".mhd", ".nrrd", ".nhdr")
SUPPORTED = PILLOW_SUFFIXES + SITK_SUFFIXES

#: Most pixels an image may hold, checked from the file's header before its pixels are decoded, so that a
#: small file cannot claim gigabytes; ``$TOPOMATCH_MAX_IMAGE_PIXELS`` overrides it.
MAX_PIXELS = 100_000_000


def max_pixels() -> int:
    return limit_from_env("TOPOMATCH_MAX_IMAGE_PIXELS", MAX_PIXELS)


def _check_size(path: Path, shape) -> None:
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
                           f"{', '.join(SUPPORTED)} or a DICOM series folder")


def file_stem(path: Path) -> str:
    """The file name without its format suffix (a folder's name for a DICOM series folder)."""
    if path.is_dir():
        return path.name
    fmt = image_format(path)
    return path.name[: -len(fmt)] if path.name.lower().endswith(fmt) else path.stem


@contextlib.contextmanager
def keep_locale():
    """Restore the process locale afterwards: ITK's GDCM calls can set it to "C" and leave it there (Python's
    default text encoding then becomes ASCII for the rest of the process)."""
    saved = locale.setlocale(locale.LC_ALL)
    try:
        yield
    finally:
        with contextlib.suppress(locale.Error):
            locale.setlocale(locale.LC_ALL, saved)


def _pixel_bytes(reader) -> int:
    """Bytes of one pixel (all its components) of the image whose header ``reader`` read."""
    import SimpleITK as sitk

    probe = sitk.Image([1] * reader.GetDimension(), reader.GetPixelID(), reader.GetNumberOfComponents())
    return sitk.GetArrayViewFromImage(probe).itemsize * reader.GetNumberOfComponents()


def _check_data_size(path: Path, reader, size: tuple[int, ...]) -> None:
    """Refuse an uncompressed MetaImage or NIfTI file holding fewer bytes of pixel data than its header declares
    (SimpleITK would zero-fill a NIfTI file, and says "No such file or directory" for a MetaImage one)."""
    fmt = image_format(path)
    if fmt == ".nii.gz":
        header = _raw_nifti_header(path)
        needed = int(header.get_data_offset()) + math.prod(_nifti_dims(header)) * int(header["bitpix"]) // 8
        if needed > 64 * 2**20 and _gzip_length(path, needed) < needed:  # before nibabel allocates the declared size
            raise InputError(path, f"truncated: the header declares {' x '.join(map(str, _nifti_dims(header)))} voxels "
                                   f"({needed:,} bytes with the header) but the file inflates to fewer")
        return
    if fmt == ".nii":  # the bytes on disk: the header's datatype and every axis (ITK's type is after scaling)
        header = _raw_nifti_header(path)
        size = _nifti_dims(header)
        declared = math.prod(size) * int(header["bitpix"]) // 8
        offset = int(header.get_data_offset())
        if offset < header.sizeof_hdr:
            raise InputError(path, f"its data offset (vox_offset {offset}) lies inside the {header.sizeof_hdr}-byte "
                                   f"header: a damaged header (the voxels would be read from the header's bytes)")
        data_file, available = path, path.stat().st_size - offset
    elif fmt in (".mha", ".mhd"):
        declared = math.prod(int(s) for s in size) * _pixel_bytes(reader)
        head = _meta_header(path)
        if head.get("compresseddata", "").lower() == "true":
            return  # the zlib stream's length says nothing of the pixels'
        name = head.get("elementdatafile", "")
        if name.upper() == "LOCAL":
            data_file, available = path, path.stat().st_size - head["_data_start"]
        elif not name or any(c in name for c in "%*") or name.upper().startswith("LIST"):
            return  # a pattern or list of slice files (each checked to be a regular file by _check_meta_header)
        else:
            data_file = path.parent / name
            available = data_file.stat().st_size - int(float(head.get("headersize", "0") or 0))
    else:
        return
    if fmt == ".nii" and available <= 0:
        raise InputError(path, f"its data offset (vox_offset {path.stat().st_size - available:,}) lies at or past the "
                               f"end of the file ({path.stat().st_size:,} bytes): a damaged header")
    if available < declared:
        dims = " x ".join(str(int(s)) for s in size)
        raise InputError(path, f"truncated: the header declares {dims} pixels ({declared:,} bytes of pixel data) but "
                               f"{data_file.name} holds {max(available, 0):,}")


def _meta_header(path: Path) -> dict:
    """The ``Key = Value`` fields of a MetaImage header (keys lower-cased), up to ElementDataFile, and
    ``_data_start``: the byte where LOCAL data begins; ``_list``: the file names after ``ElementDataFile = LIST``."""
    data = path.read_bytes()[:1 << 20]
    fields: dict = {}
    at = 0
    for raw in data.split(b"\n"):
        at += len(raw) + 1
        key, sep, value = raw.decode("latin-1").partition("=")
        if not sep:
            if fields.get("elementdatafile", "").upper().startswith("LIST") and raw.strip():
                fields["_list"].append(raw.strip().decode("utf-8", "replace"))
            continue
        fields[key.strip().lower()] = value.strip()
        if key.strip().lower() == "elementdatafile":
            fields["_data_start"] = at
            fields["_list"] = []
            if not value.strip().upper().startswith("LIST"):
                break
    fields.setdefault("_data_start", at)
    return fields


def _check_meta_header(path: Path) -> None:
    """A MetaImage header's numbers checked before ITK parses it (ITK crashes on NDims outside 1-4, and turns a
    negative spacing or a NaN origin into 1 and 0 silently); its data files must be regular files (a FIFO
    would block the read)."""
    head = _meta_header(path)

    def fail(problem: str):
        raise InputError(path, f"cannot read image (its MetaImage header: {problem})")

    def numbers(key):
        try:
            return [float(v) for v in head[key].split()] if key in head else []
        except ValueError:
            fail(f"{key} = {head[key][:60]!r} is not a list of numbers")

    try:
        ndims = int(head.get("ndims", "0"))
    except ValueError:
        ndims = 0
    if not 2 <= ndims <= 4:
        fail(f"NDims = {head.get('ndims', '(missing)')!r}; an image to register has 2 to 4 dimensions")
    sizes = numbers("dimsize")
    if len(sizes) != ndims or any(v < 1 or v != int(v) for v in sizes):
        fail(f"DimSize = {head.get('dimsize', '(missing)')!r}; {ndims} positive whole numbers are needed")
    for key in ("elementspacing", "elementsize"):
        values = numbers(key)
        if values and (len(values) < ndims or not all(math.isfinite(v) and v > 0 for v in values[:ndims])):
            fail(f"{key} = {head[key][:60]!r}; {ndims} finite positive spacings are needed")
    for key in ("offset", "origin", "position", "transformmatrix", "rotation", "orientation"):
        values = numbers(key)
        if values and not all(math.isfinite(v) for v in values):
            fail(f"{key} = {head[key][:60]!r} is not finite")
        if key in ("transformmatrix", "rotation", "orientation") and len(values) == ndims * ndims \
                and abs(np.linalg.det(np.reshape(values, (ndims, ndims)))) < 1e-6:
            fail(f"{key} = {head[key][:60]!r} is singular, not a rotation")
    name = head.get("elementdatafile", "")
    files = head["_list"] if name.upper().startswith("LIST") else (
        [] if not name or name.upper() == "LOCAL" or any(c in name for c in "%*") else [name])
    for f in files:
        target = path.parent / f
        if not target.is_file():
            fail(f"its pixel data file {target} (ElementDataFile) is "
                 f"{'not a regular file' if target.exists() else 'missing'}")


def _check_nrrd_header(path: Path) -> None:
    """A detached NRRD's data file(s) must be regular files (a FIFO would block the read)."""
    text = path.read_bytes()[:1 << 20].split(b"\n\n")[0].decode("latin-1")
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep and key.strip().lower() in ("data file", "datafile"):
            value = value.strip()
            if value.upper().startswith("LIST") or "%" in value:
                return
            target = path.parent / value
            if not target.is_file():
                raise InputError(path, f"its data file {target} is {'not a regular file' if target.exists() else 'missing'}")


def check_header(path: Path) -> None:
    """What can be checked of a file's header before ITK or nibabel parse it (ITK crashes on some MetaImage
    headers and blocks on a FIFO named as a data file): MetaImage and detached-NRRD headers, the NIfTI header."""
    fmt = image_format(path)
    if fmt in (".mha", ".mhd"):
        _check_meta_header(path)
    elif fmt in (".nrrd", ".nhdr"):
        _check_nrrd_header(path)
    elif fmt in (".nii", ".nii.gz"):
        _check_nifti_header(path, _raw_nifti_header(path))


def _gzip_length(path: Path, enough: int) -> int:
    """How many bytes a gzip file inflates to, counted in 1 MiB pieces and stopped at ``enough`` (nothing kept)."""
    import gzip

    total = 0
    try:
        with gzip.open(path, "rb") as fh:
            while total < enough and (piece := fh.read(1 << 20)):
                total += len(piece)
    except (OSError, EOFError, ValueError):  # a damaged stream: what inflated before it
        pass
    return total


def check_geometry(path: str | Path, spacing, origin, direction) -> None:
    """Refuse spacings outside 1e-6 to 1e6 mm, an origin that is not finite or beyond 1e9 mm (there double precision
    keeps less than a micrometre), and a direction that is not a rotation; ``path`` names the image (a file, or an
    image in memory)."""
    bad = [f"{s:g}" for s in spacing if not (math.isfinite(s) and 1e-6 <= s <= 1e6)]
    if bad:
        raise InputError(path, f"pixel spacing {', '.join(f'{s:g}' for s in spacing)} mm: every spacing must be a "
                               f"finite number from 1e-6 to 1e6 mm; fix the header (or the Image's spacing)")
    if not all(math.isfinite(o) and abs(o) <= 1e9 for o in origin):
        raise InputError(path, f"origin {tuple(float(o) for o in origin)} is not finite or lies beyond 1e9 mm; fix "
                               f"the header (or the Image's origin)")
    d = np.asarray(direction, dtype=float).reshape(len(spacing), len(spacing))
    if not (np.all(np.isfinite(d)) and np.allclose(d.T @ d, np.eye(len(d)), atol=1e-3)):
        raise InputError(path, "direction matrix is not a rotation (non-finite, singular or sheared); fix the header")


def _sitk_detail(exc: Exception) -> str:
    lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "SimpleITK could not read it"


def _dicom_files(folder: Path) -> list[str]:
    """The file names of the one DICOM series in ``folder`` (InputError for none or several)."""
    import SimpleITK as sitk

    shown = sitk.ProcessObject.GetGlobalWarningDisplay()
    sitk.ProcessObject.SetGlobalWarningDisplay(False)  # GDCM's "No Series were found" on stderr: the error says it
    try:
        ids = sitk.ImageSeriesReader.GetGDCMSeriesIDs(str(folder))
    finally:
        sitk.ProcessObject.SetGlobalWarningDisplay(shown)
    if not ids:
        raise InputError(folder, "is a folder without a DICOM series; give a DICOM series folder or an image file")
    if len(ids) > 1:
        counts = [f"{sid} ({len(sitk.ImageSeriesReader.GetGDCMSeriesFileNames(str(folder), sid))} files)"
                  for sid in ids]
        raise InputError(folder, f"holds {len(ids)} DICOM series ({'; '.join(counts)}); a registration input is one "
                                 f"series: put each series in its own folder")
    return list(sitk.ImageSeriesReader.GetGDCMSeriesFileNames(str(folder), ids[0]))


def _check_slice_spacing(folder: Path, files: list[str]) -> None:
    """Refuse a DICOM series whose slices do not make one regular grid: positions (ImagePositionPatient) not
    finite or not evenly spaced along the slice normal (a missing or repeated slice), orientations
    (ImageOrientationPatient) or pixel spacings (PixelSpacing) that differ between slices or are not positive.
    ITK reads such a series as a regular grid (the average step, the first slice's orientation and spacing),
    and every position past the fault would be wrong."""
    import SimpleITK as sitk

    def tag(reader, key: str) -> list[float] | None:
        if not reader.HasMetaDataKey(key):
            return None
        try:
            return [float(v) for v in reader.GetMetaData(key).split("\\")]
        except ValueError:
            return [math.nan]

    def fail(problem: str):
        raise InputError(folder, f"its {len(files)} DICOM slices do not make one volume: {problem}; registration needs "
                                 f"a complete, regular series")

    if len(files) < 2:
        return
    positions, orientations, spacings = [], [], []
    for name in files:
        reader = sitk.ImageFileReader()
        reader.SetFileName(name)
        reader.ReadImageInformation()
        positions.append(tag(reader, "0020|0032"))
        orientations.append(tag(reader, "0020|0037"))
        spacings.append(tag(reader, "0028|0030"))
    for label, values in (("PixelSpacing", spacings), ("ImageOrientationPatient", orientations)):
        present = [v for v in values if v is not None]
        if not present:
            continue
        first = np.asarray(present[0])
        if len(present) < len(values) or any(len(v) != len(first) for v in present):
            fail(f"{label} is missing or malformed in {sum(v is None for v in values)} of them")
        if not np.all(np.isfinite(present)):
            fail(f"{label} is not finite in {sum(not np.all(np.isfinite(v)) for v in present)} of them")
        if label == "PixelSpacing" and not np.all(np.asarray(present) > 0):
            fail(f"PixelSpacing {present[0]} is not positive")
        odd = [i for i, v in enumerate(present) if np.max(np.abs(np.asarray(v) - first)) > 1e-4 * max(1.0, np.abs(first).max())]
        if odd:
            fail(f"slice file {Path(files[odd[0]]).name} has {label} {present[odd[0]]}, the first {[float(x) for x in first]}")
    if any(p is None for p in positions) or orientations[0] is None:
        return  # no positions to check (ITK falls back on the file order and the slice thickness)
    if not all(len(p) == 3 and np.all(np.isfinite(p)) for p in positions):
        bad = next(i for i, p in enumerate(positions) if not (len(p) == 3 and np.all(np.isfinite(p))))
        fail(f"slice file {Path(files[bad]).name} has ImagePositionPatient {positions[bad]}")
    o = np.asarray(orientations[0])
    along = np.asarray(positions) @ np.cross(o[:3], o[3:6])
    steps = np.diff(np.sort(along))
    typical = float(np.median(steps))
    if typical <= 1e-6:
        fail("the slices share one position along their normal (ImagePositionPatient): not a stack")
    odd = np.flatnonzero(np.abs(steps - typical) > 0.01 * typical)
    if len(odd):
        k = int(odd[0])
        fail(f"not evenly spaced: {steps[k]:g} mm between slices {k} and {k + 1} (in position order) where the others "
             f"are {typical:g} mm apart: a missing or repeated slice")


def _checked(path: str | Path) -> Path:
    path = Path(path)
    if path.is_dir():
        return path
    path = check_readable_file(path)
    if path.stat().st_size == 0:
        raise InputError(path, "file is empty (0 bytes)")
    image_format(path)
    return path


def _read_pillow(path: Path) -> np.ndarray:
    from PIL import Image as PILImage
    from PIL import UnidentifiedImageError

    PILImage.MAX_IMAGE_PIXELS = max_pixels()  # Pillow's own bomb check never fires before ours
    try:
        with PILImage.open(path) as im:
            _check_size(path, (im.size[1], im.size[0]))
            im.load()
            if getattr(im, "n_frames", 1) > 1:
                raise InputError(path, f"multi-page image with {im.n_frames} pages; registration reads one image")
            if im.mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif im.mode in ("LA", "PA"):
                im = im.convert("L")
            elif im.mode == "CMYK":
                im = im.convert("RGB")
            return np.asarray(im)
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise InputError(path, f"cannot read image ({type(exc).__name__}: {exc})") from None


def read_array(path: str | Path) -> tuple[np.ndarray, tuple[float, ...], tuple[float, ...], np.ndarray]:
    """The grey pixel array of a file (SimpleITK's array order, axes of one pixel dropped) and its spacing,
    origin and direction (ITK order, over the kept axes)."""
    path = _checked(path)
    fmt = "" if path.is_dir() else image_format(path)
    if fmt in PILLOW_SUFFIXES:
        try:
            arr = _read_pillow(path)
            if arr.ndim == 3 and arr.shape[-1] in (3, 4) and min(arr.shape[:2]) > 4:
                arr = arr[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
            return arr, (1.0,) * arr.ndim, (0.0,) * arr.ndim, np.eye(arr.ndim)
        except InputError:
            if fmt not in (".tif", ".tiff"):
                raise  # TIFF variants Pillow cannot decode go to SimpleITK
    arr, spacing, origin, direction = _read_nifti(path) if fmt in (".nii", ".nii.gz") else _read_with_sitk(path)
    check_geometry(path, spacing[:arr.ndim], origin[:arr.ndim], np.asarray(direction).reshape(
        int(round(len(np.ravel(direction)) ** 0.5)), -1)[:arr.ndim, :arr.ndim])
    d = arr.ndim
    keep = [a for a in range(d) if arr.shape[d - 1 - a] > 1]  # ITK axes of more than one pixel
    direction = np.asarray(direction).reshape(d, d)[np.ix_(keep, keep)]
    if len(keep) < d and not abs(np.linalg.det(direction)) > 1e-6:
        direction = np.eye(len(keep))
    arr = arr.reshape([arr.shape[d - 1 - a] for a in reversed(keep)])
    return arr, tuple(spacing[a] for a in keep), tuple(origin[a] for a in keep), direction


def _read_with_sitk(path: Path):
    """Pixels (SimpleITK's array order; colour as luminance), spacing, origin, direction of a file or DICOM series
    folder SimpleITK reads (a trailing axis of one dropped)."""
    import SimpleITK as sitk

    try:
        with keep_locale():
            if not path.is_dir():
                check_header(path)
            reader = sitk.ImageFileReader()
            files = _dicom_files(path) if path.is_dir() else [str(path)]
            if path.is_dir():
                _check_slice_spacing(path, files)
            reader.SetFileName(files[0])
            reader.ReadImageInformation()
            components = reader.GetNumberOfComponents()
            size = tuple(reader.GetSize()[:2]) + (len(files),) if path.is_dir() else tuple(reader.GetSize())
            _check_size(path, size + ((components,) if components > 1 else ()))
            if not path.is_dir():
                _check_data_size(path, reader, size)
            image = sitk.ReadImage(files) if path.is_dir() else reader.Execute()
    except RuntimeError as exc:
        raise InputError(path, f"cannot read image ({_sitk_detail(exc)})") from None
    if image.GetDimension() == 4:
        if image.GetSize()[3] != 1:
            raise InputError(path, f"is a 4D image ({' x '.join(map(str, image.GetSize()))}: {image.GetSize()[3]} "
                                   f"volumes, e.g. a time series); extract one 3D volume first (e.g. sitk.Extract)")
        image = sitk.Extract(image, list(image.GetSize()[:3]) + [0], [0, 0, 0, 0])
    arr = sitk.GetArrayFromImage(image)
    components = image.GetNumberOfComponentsPerPixel()
    if components > 1:
        if image.GetDimension() != 2 or components not in (3, 4):
            raise InputError(path, f"has {components} components per pixel (colour or vector data); registration "
                                   f"needs one intensity per pixel")
        arr = arr[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    return arr, image.GetSpacing(), image.GetOrigin(), image.GetDirection()


def _read_nifti(path: Path):
    """A NIfTI file's voxels read by nibabel (SimpleITK's reader turns NaN into 0 and zero-fills a truncated file),
    in SimpleITK's array order, with the geometry as SimpleITK reads the header (no pixels read by it)."""
    import nibabel as nib
    import SimpleITK as sitk

    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    try:
        check_header(path)  # the raw NIfTI header, before nibabel or ITK "repair" it on reading
        reader.ReadImageInformation()
        _check_data_size(path, reader, tuple(reader.GetSize()))
        data = np.asarray(nib.load(str(path)).dataobj)
    except InputError:
        raise
    except Exception as exc:  # SimpleITK's RuntimeError, nibabel's many types for a damaged file
        detail = _sitk_detail(exc) if isinstance(exc, RuntimeError) else f"{type(exc).__name__}: {exc}"
        raise InputError(path, f"cannot read image ({detail})") from None
    while data.ndim > 3 and data.shape[-1] == 1:
        data = data[..., 0]
    if data.ndim > 3:
        raise InputError(path, f"is a {data.ndim}D image ({' x '.join(map(str, data.shape))}: {data.shape[3]} volumes, "
                               f"e.g. a time series); extract one 3D volume first (e.g. sitk.Extract or fslroi)")
    if data.dtype.names:
        raise InputError(path, f"has {len(data.dtype.names)} components per voxel (colour or vector data); "
                               f"registration needs one intensity per voxel")
    d, n = data.ndim, reader.GetDimension()
    direction = np.array(reader.GetDirection()).reshape(n, n)[:d, :d]
    return data.T, reader.GetSpacing()[:d], reader.GetOrigin()[:d], direction


def _raw_nifti_header(path: Path):
    """The NIfTI-1 or NIfTI-2 header of ``path`` as written (nibabel's ``load`` sets a zero voxel size to 1 and a
    negative one to its absolute value, and says so on stdout)."""
    import nibabel as nib
    from nibabel.openers import ImageOpener

    try:
        with ImageOpener(str(path)) as f:
            raw = f.read(540)
    except Exception as exc:  # gzip's BadGzipFile / zlib.error / EOFError for a damaged or mislabelled .nii.gz
        raise InputError(path, f"cannot read image ({type(exc).__name__}: {exc})") from None
    for cls in (nib.Nifti1Header, nib.Nifti2Header):
        for order in ("<", ">"):
            size = np.frombuffer(raw[:4], dtype=f"{order}i4")[0]
            if size == cls.sizeof_hdr and len(raw) >= size:
                return cls.from_fileobj(BytesIO(raw[:size]), check=False)
    raise InputError(path, "cannot read image (not a NIfTI file: its first four bytes are not the size of a NIfTI-1 "
                           "or NIfTI-2 header)")


def _nifti_dims(header) -> tuple[int, ...]:
    """The sizes of every axis the header declares (dim[1] .. dim[dim[0]]): vectors and time points included."""
    n = int(header["dim"][0])
    return tuple(int(v) for v in header["dim"][1:1 + max(1, min(n, 7))])


def _check_nifti_header(path: Path, header) -> None:
    """Refuse voxel sizes (pixdim) that are not finite and positive (nibabel and ITK would silently read 0 as 1
    and keep a negative one); warn when the header has neither a qform nor an sform (ITK then reads the voxel
    axes as the scanner's, origin 0: the registration's translation is relative to that assumption)."""
    if header.sizeof_hdr == 540:
        raise InputError(path, "is a NIfTI-2 file, which this SimpleITK build cannot read; save it as NIfTI-1 (e.g. "
                               "nibabel: nib.save(nib.Nifti1Image(img.dataobj, img.affine), 'out.nii.gz'))")
    if not math.isfinite(float(header["vox_offset"])) or float(header["vox_offset"]) < 0:
        raise InputError(path, f"its data offset (vox_offset {float(header['vox_offset'])}) is not a byte position: a "
                               f"damaged header")
    d = int(header["dim"][0])
    pixdim = [float(v) for v in header["pixdim"][1:1 + min(max(d, 1), 3)]]
    if not all(math.isfinite(v) and v > 0 for v in pixdim):
        raise InputError(path, f"the header's voxel sizes (pixdim) are {', '.join(f'{v:g}' for v in pixdim)}: each "
                               f"must be a finite positive number of mm; fix the header (e.g. nibabel's set_zooms)")
    dims = _nifti_dims(header)
    if not 1 <= int(header["dim"][0]) <= 7 or any(v < 1 for v in dims):
        raise InputError(path, f"the header's dimensions are dim = {[int(v) for v in header['dim']]}: dim[0] must be 1 "
                               f"to 7 and each size at least 1")
    _check_size(path, dims)  # every axis counts: a vector or time axis multiplies the bytes read
    if int(header["qform_code"]) > 0:
        q = [float(header[k]) for k in ("quatern_b", "quatern_c", "quatern_d", "qoffset_x", "qoffset_y", "qoffset_z")]
        if not all(math.isfinite(v) for v in q):
            raise InputError(path, f"the qform (quaternion and offset {q}) is not finite: a damaged header")
        if max(abs(v) for v in q[3:]) > 1e9:  # ITK would report "orthonormal direction cosines", naming another field
            raise InputError(path, f"the qform's origin (qoffset {q[3:]}) lies beyond 1e9 mm: a damaged header")
    if int(header["sform_code"]) > 0:
        srow = np.array([header["srow_x"], header["srow_y"], header["srow_z"]], dtype=float)
        if not np.all(np.isfinite(srow)) or abs(np.linalg.det(srow[:, :3])) < 1e-12:
            raise InputError(path, "the sform (srow_x/y/z) is not finite or its 3 x 3 part is singular: a damaged header")
        if np.max(np.abs(srow[:, 3])) > 1e9:
            raise InputError(path, f"the sform's origin ({srow[:, 3].tolist()}) lies beyond 1e9 mm: a damaged header")
    if int(header["qform_code"]) == 0 and int(header["sform_code"]) == 0:
        warnings.warn(f"{path}: the NIfTI header has neither a qform nor an sform, so its orientation is unknown; it "
                      f"is read as ITK reads it (voxel axes = scanner axes, origin 0, spacing {pixdim} mm): the "
                      f"registration's rotation and translation are relative to that assumption", InputWarning,
                      stacklevel=3)


def image_dimension(path: str | Path) -> int:
    """How many axes of more than one pixel the image at ``path`` has (from its header; 3 for a DICOM series
    folder, 2 for the Pillow formats). InputError if unreadable."""
    path = _checked(path)
    if path.is_dir():
        with keep_locale():
            _dicom_files(path)  # a folder is an input only if it holds one DICOM series
        return 3
    if image_format(path) in PILLOW_SUFFIXES:
        return 2
    import SimpleITK as sitk  # here: importing it costs ~0.06 s, a third of a 2D registration

    check_header(path)
    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    try:
        with keep_locale():
            reader.ReadImageInformation()
    except RuntimeError as exc:
        raise InputError(path, f"cannot read image ({_sitk_detail(exc)})") from None
    return sum(1 for s in reader.GetSize() if s > 1)


def output_suffix(path: str | Path) -> str:
    """The suffix of an image written "in the input's format": its own (``.mhd`` -> ``.mha``, ``.nhdr`` ->
    ``.nrrd``), ``.nii.gz`` for DICOM, ``.png`` for Pillow formats."""
    path = Path(path)
    if path.is_dir():
        return ".nii.gz"
    fmt = image_format(path)
    if fmt in PILLOW_SUFFIXES:
        return ".png"
    return {".mhd": ".mha", ".nhdr": ".nrrd", ".dcm": ".nii.gz", ".dicom": ".nii.gz", ".ima": ".nii.gz"}.get(fmt, fmt)
