"""Reading images, 2D and 3D: every format gives float64 in SimpleITK's array order with ITK's geometry (spacing,
origin, direction as SimpleITK reads them); DICOM series folders; every failure names the file."""

from __future__ import annotations

import numpy as np
import pytest

from tests_paths import ITK_DIR
from topomatch.pipeline.errors import InputError
from topomatch.stages.imaging.files import keep_locale
from topomatch.stages.registration.io import (LoadImageParams, LoadPairParams, load_image, load_pair, read_image,
                                              read_pair, read_volume)

sitk = pytest.importorskip("SimpleITK")


def _ramp(h=24, w=32):
    rows, cols = np.mgrid[0:h, 0:w]
    return (3 * rows + 5 * cols).astype(np.float64)


def test_bundled_png(itk_dir):
    im = read_image(itk_dir / "BrainProtonDensitySlice.png")
    assert im.shape == (217, 181) and im.data.dtype == np.float64 and im.data.flags.c_contiguous
    assert im.spacing == (1.0, 1.0) and im.origin == (0.0, 0.0) and im.name == "BrainProtonDensitySlice"
    assert tuple(im.center) == (90.0, 108.0)


@pytest.mark.parametrize("mode,dtype,suffix", [("L", np.uint8, ".png"), ("I;16", np.uint16, ".png"),
                                               ("F", np.float32, ".tif"), ("L", np.uint8, ".tiff")])
def test_pillow_formats_round_trip(tmp_path, mode, dtype, suffix):
    from PIL import Image as PILImage

    data = _ramp().astype(dtype)
    path = tmp_path / f"ramp{suffix}"
    PILImage.fromarray(data).save(path)
    np.testing.assert_array_equal(read_image(path).data, data.astype(np.float64))


def test_rgb_becomes_luminance(tmp_path):
    from PIL import Image as PILImage

    rgb = np.zeros((10, 12, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[:5, :, 2] = 100, 50, 200
    PILImage.fromarray(rgb).save(tmp_path / "rgb.png")
    im = read_image(tmp_path / "rgb.png")
    np.testing.assert_allclose(im.data[0, 0], 0.299 * 100 + 0.587 * 50 + 0.114 * 200)
    np.testing.assert_allclose(im.data[9, 0], 0.299 * 100 + 0.587 * 50)


def test_nifti_matches_simpleitk_array_and_spacing(itk_dir):
    import SimpleITK as sitk

    path = itk_dir / "KmeansTest_T1UCharRaw.nii.gz"
    ref = sitk.ReadImage(str(path))
    arr = sitk.GetArrayFromImage(ref)  # (k, j, i)
    im = read_image(path, slice_index=30)
    np.testing.assert_array_equal(im.data, arr[30])
    assert im.spacing == ref.GetSpacing()[:2] == (2.0, 2.0)  # (i, j): ITK order
    assert "slice 30" in im.source
    other_axis = read_image(path, slice_index=64, axis=2)
    np.testing.assert_array_equal(other_axis.data, arr[:, :, 64])
    assert other_axis.spacing == (2.0, 3.0)  # (j, k)


@pytest.mark.parametrize("suffix", [".mha", ".nrrd", ".dcm"])
def test_simpleitk_formats_keep_spacing(tmp_path, suffix):
    import SimpleITK as sitk

    data = _ramp().astype(np.int16)
    img = sitk.GetImageFromArray(data)
    img.SetSpacing((0.5, 0.75))  # (x = col, y = row)
    path = tmp_path / f"ramp{suffix}"
    sitk.WriteImage(img, str(path))
    im = read_image(path)
    np.testing.assert_array_equal(im.data, data)
    assert im.spacing == pytest.approx((0.5, 0.75))


def test_nifti_2d_written_by_nibabel(tmp_path):
    import nibabel as nib

    data = _ramp().T.astype(np.float32)  # nibabel's (i, j) = (x, y) = (col, row)
    nib.save(nib.Nifti1Image(data[:, :, None], np.diag([0.9, 1.1, 1.0, 1.0])), tmp_path / "slice.nii")
    im = read_image(tmp_path / "slice.nii")
    np.testing.assert_array_equal(im.data, _ramp())
    assert im.spacing == pytest.approx((0.9, 1.1))


def test_missing_unreadable_empty_unsupported(tmp_path):
    with pytest.raises(InputError, match="nope.png: file not found"):
        read_image(tmp_path / "nope.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(InputError, match="empty.png: file is empty"):
        read_image(tmp_path / "empty.png")
    (tmp_path / "garbage.png").write_bytes(b"this is not a png" * 10)
    with pytest.raises(InputError, match="garbage.png: cannot read image"):
        read_image(tmp_path / "garbage.png")
    (tmp_path / "garbage.nii").write_bytes(b"\x00" * 400)
    with pytest.raises(InputError, match="garbage.nii: cannot read image"):
        read_image(tmp_path / "garbage.nii")
    (tmp_path / "garbage.mha").write_bytes(b"ObjectType = Image\nNDims = x\n")
    with pytest.raises(InputError, match="garbage.mha: cannot read image"):
        read_image(tmp_path / "garbage.mha")
    (tmp_path / "image.xyz").write_bytes(b"1")
    with pytest.raises(InputError, match="unsupported image format '.xyz'"):
        read_image(tmp_path / "image.xyz")


def test_nan_constant_and_tiny_images_rejected(tmp_path):
    from PIL import Image as PILImage

    data = _ramp().astype(np.float32)
    data[3, 4] = np.nan
    data[5, 6] = np.inf
    PILImage.fromarray(data).save(tmp_path / "nan.tif")
    with pytest.raises(InputError, match=r"nan.tif: 2 of 768 pixels are NaN or infinite"):
        read_image(tmp_path / "nan.tif")
    PILImage.fromarray(np.full((20, 20), 7, np.uint8)).save(tmp_path / "flat.png")
    with pytest.raises(InputError, match=r"flat.png: image is constant \(every pixel is 7\)"):
        read_image(tmp_path / "flat.png")
    PILImage.fromarray(np.arange(6, dtype=np.uint8).reshape(2, 3)).save(tmp_path / "tiny.png")
    with pytest.raises(InputError, match="tiny.png: image is too small"):
        read_image(tmp_path / "tiny.png")


def test_a_volume_is_3d_and_a_slice_2d():
    path = ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz"
    assert read_image(path).dim == 3 and read_image(path).shape == (62, 128, 128)
    with pytest.raises(InputError, match="slice 62 is out of range: the volume has 62 slices"):
        read_image(path, slice_index=62)
    assert read_image(path, slice_index=-1).shape == (128, 128)


def test_load_pair_rejects_different_dimensionality(itk_dir):
    png, vol = itk_dir / "BrainT1Slice.png", itk_dir / "KmeansTest_T1UCharRaw.nii.gz"
    with pytest.raises(InputError) as err:
        load_pair(str(png), str(vol), params=LoadPairParams())
    msg = str(err.value)
    assert "KmeansTest_T1UCharRaw.nii.gz" in msg and "3D" in msg and "BrainT1Slice.png is 2D" in msg
    assert "moving_slice" in msg
    pair = load_pair(str(png), str(vol), params=LoadPairParams(moving_slice=30))
    assert pair.fixed.shape == (217, 181) and pair.moving.shape == (128, 128)


def test_load_image_stage_ignores_slice_for_2d(itk_dir):
    res = load_image(str(itk_dir / "BrainT1Slice.png"), params=LoadImageParams(slice=31))
    assert res.image.shape == (217, 181)
    assert res.summary()["size"] == "181x217"


@pytest.mark.data
def test_data_root_metaimage_and_nifti(data_root):
    lung = read_image(data_root / "images/itk_examples_data/RatLungSlice1.mha")
    assert lung.shape == (128, 128) and lung.data.max() > lung.data.min()
    with pytest.raises(InputError, match=r"too small to register \(shape \(3, 217, 181\).*register one slice"):
        read_image(data_root / "images/itk_examples_data/BrainProtonDensity3Slices.mha")
    three = read_image(data_root / "images/itk_examples_data/BrainProtonDensity3Slices.mha", slice_index=1)
    assert three.shape == (217, 181)
    anat = read_image(data_root / "images/nibabel_testdata/anatomical.nii", slice_index=12)
    assert anat.spacing == (2.0, 2.0)


def _volume(shape=(10, 12, 14), spacing=(2.0, 2.0, 3.0), origin=(5.0, -3.0, 7.0), seed=0):
    rng = np.random.default_rng(seed)
    img = sitk.GetImageFromArray(rng.uniform(0, 100, shape).astype(np.float32))
    img.SetSpacing(spacing)
    img.SetOrigin(origin)
    img.SetDirection((1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0))
    return img


def write_dicom_series(image, folder, series_uid: str, *, first_instance: int = 1) -> None:
    """One file per slice with the tags a DICOM reader needs to stack them (SimpleITK's DicomSeriesFromArray recipe)."""
    with keep_locale():  # GDCM's writer leaves the process locale at "C"
        img = sitk.Cast(sitk.RescaleIntensity(image, 0, 1000), sitk.sitkInt16)
        direction = img.GetDirection()
        writer = sitk.ImageFileWriter()
        writer.KeepOriginalImageUIDOn()
        folder.mkdir(parents=True, exist_ok=True)
        for k in range(img.GetDepth()):
            s = img[:, :, k]
            s.SetMetaData("0008|0060", "MR")
            s.SetMetaData("0020|000d", "1.2.826.0.1.3680043.2.1125.1")
            s.SetMetaData("0020|000e", series_uid)
            s.SetMetaData("0020|0037", "\\".join(map(str, (direction[0], direction[3], direction[6], direction[1],
                                                            direction[4], direction[7]))))
            s.SetMetaData("0020|0032", "\\".join(map(str, img.TransformIndexToPhysicalPoint((0, 0, k)))))
            s.SetMetaData("0020|0013", str(first_instance + k))
            s.SetMetaData("0008|0018", f"{series_uid}.{k}")
            writer.SetFileName(str(folder / f"{series_uid[-3:]}_{k:03d}.dcm"))
            writer.Execute(s)


def test_read_volume_keeps_simpleitk_geometry():
    path = ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz"
    vol, img = read_volume(path), sitk.ReadImage(str(path))
    assert vol.size == img.GetSize() == (128, 128, 62) and vol.spacing == img.GetSpacing() == (2.0, 2.0, 3.0)
    assert vol.origin == img.GetOrigin()
    np.testing.assert_array_equal(vol.direction.ravel(), img.GetDirection())
    np.testing.assert_array_equal(vol.data, sitk.GetArrayFromImage(img))
    assert vol.name == "KmeansTest_T1UCharRaw"


@pytest.mark.parametrize("suffix", [".mha", ".nrrd", ".nii.gz"])
def test_volume_formats_round_trip(tmp_path, suffix):
    img = _volume()
    sitk.WriteImage(img, str(tmp_path / f"v{suffix}"))
    vol = read_volume(tmp_path / f"v{suffix}")
    np.testing.assert_allclose(vol.physical(np.array([[3.0, 4.0, 5.0]]))[0],
                               img.TransformIndexToPhysicalPoint((3, 4, 5)), atol=1e-4)
    np.testing.assert_allclose(vol.data, sitk.GetArrayFromImage(img), rtol=1e-6)


def test_dicom_series_folder_and_mixed_series(tmp_path):
    img = _volume(shape=(6, 12, 14), origin=(0.0, 0.0, 0.0))
    img.SetDirection((1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0))
    write_dicom_series(img, tmp_path / "one", "1.2.826.0.1.3680043.2.1125.2.111")
    import locale

    before = locale.setlocale(locale.LC_ALL)
    vol = read_volume(tmp_path / "one")
    assert locale.setlocale(locale.LC_ALL) == before  # GDCM's reader does not change the process locale
    assert vol.size == (14, 12, 6)
    np.testing.assert_allclose(vol.spacing, (2.0, 2.0, 3.0), atol=1e-6)
    write_dicom_series(img, tmp_path / "mixed", "1.2.826.0.1.3680043.2.1125.2.111")
    write_dicom_series(_volume(shape=(4, 12, 14), seed=1), tmp_path / "mixed", "1.2.826.0.1.3680043.2.1125.2.222")
    with pytest.raises(InputError, match=r"mixed: holds 2 DICOM series"):
        read_volume(tmp_path / "mixed")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"empty: is a folder without a DICOM series"):
        read_volume(tmp_path / "empty")


def test_bad_volumes_raise_input_errors_naming_the_file(tmp_path):
    import nibabel as nib

    nib.save(nib.Nifti1Image(np.random.default_rng(0).normal(size=(6, 6, 6, 3)).astype(np.float32), np.eye(4)),
             tmp_path / "four.nii.gz")
    with pytest.raises(InputError, match=r"four.nii.gz: is a 4D image \(6 x 6 x 6 x 3: 3 volumes"):
        read_volume(tmp_path / "four.nii.gz")
    nib.save(nib.Nifti1Image(np.full((1, 1, 1), 7, dtype=np.int16), np.eye(4)), tmp_path / "one.nii")
    with pytest.raises(InputError, match=r"one.nii: is a 0D image of shape \(\) once its axes of one pixel are dropped: "
                                         r"too small to register"):
        read_volume(tmp_path / "one.nii")
    nib.save(nib.Nifti1Image(np.full((6, 6, 6), 7, dtype=np.int16), np.eye(4)), tmp_path / "flat.nii")
    with pytest.raises(InputError, match=r"flat.nii: image is constant"):
        read_volume(tmp_path / "flat.nii")
    sitk.WriteImage(_volume(), str(tmp_path / "ok.mha"))
    sitk.WriteImage(sitk.Cast(_volume()[:, :, 0], sitk.sitkUInt8), str(tmp_path / "flat2d.png"))
    with pytest.raises(InputError, match=r"ok.mha: the fixed image is 3D but the moving image flat2d.png is 2D"):
        read_pair(tmp_path / "ok.mha", tmp_path / "flat2d.png")
    with pytest.raises(InputError, match=r"flat2d.png: is a 2D image"):
        read_volume(tmp_path / "flat2d.png")
    with pytest.raises(InputError, match=r"missing.nii: file not found"):
        read_pair(tmp_path / "ok.mha", tmp_path / "missing.nii")


def test_load_pair_reads_two_volumes_with_their_geometry(tmp_path):
    sitk.WriteImage(_volume(), str(tmp_path / "a.nrrd"))
    sitk.WriteImage(_volume(seed=1), str(tmp_path / "b.mha"))
    pair = load_pair(str(tmp_path / "a.nrrd"), str(tmp_path / "b.mha"), params=LoadPairParams())
    assert pair.fixed.dim == pair.moving.dim == 3 and pair.fixed.spacing == (2.0, 2.0, 3.0)
    assert pair.summary()["fixed_size"] == "14x12x10"
