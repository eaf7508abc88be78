"""Reading images: every format gives float64 [row, col] and its spacing; every failure names the file."""

from __future__ import annotations

import numpy as np
import pytest

from topomatch.pipeline.errors import InputError
from topomatch.stages.registration.io import LoadImageParams, LoadPairParams, load_image, load_pair, read_image


def _ramp(h=24, w=32):
    rows, cols = np.mgrid[0:h, 0:w]
    return (3 * rows + 5 * cols).astype(np.float64)


def test_bundled_png(itk_dir):
    im = read_image(itk_dir / "BrainProtonDensitySlice.png")
    assert im.shape == (217, 181) and im.data.dtype == np.float64 and im.data.flags.c_contiguous
    assert im.spacing == (1.0, 1.0) and im.name == "BrainProtonDensitySlice"
    assert im.center == (90.0, 108.0)


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
    assert im.spacing == (ref.GetSpacing()[1], ref.GetSpacing()[0]) == (2.0, 2.0)
    assert "slice 30" in im.source
    other_axis = read_image(path, slice_index=64, axis=2)
    np.testing.assert_array_equal(other_axis.data, arr[:, :, 64])
    assert other_axis.spacing == (3.0, 2.0)


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
    assert im.spacing == pytest.approx((0.75, 0.5))


def test_nifti_2d_written_by_nibabel(tmp_path):
    import nibabel as nib

    data = _ramp().T.astype(np.float32)  # nibabel's (i, j) = (x, y) = (col, row)
    nib.save(nib.Nifti1Image(data[:, :, None], np.diag([0.9, 1.1, 1.0, 1.0])), tmp_path / "slice.nii")
    im = read_image(tmp_path / "slice.nii")
    np.testing.assert_array_equal(im.data, _ramp())
    assert im.spacing == pytest.approx((1.1, 0.9))


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
    with pytest.raises(InputError, match="garbage.nii: cannot read NIfTI"):
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


def test_volume_needs_a_slice(itk_dir):
    path = itk_dir / "KmeansTest_T1UCharRaw.nii.gz"
    with pytest.raises(InputError, match=r"KmeansTest_T1UCharRaw.nii.gz: is a 3D volume of shape \(62, 128, 128\)"):
        read_image(path)
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
    assert res.summary()["rows"] == 217


@pytest.mark.data
def test_data_root_metaimage_and_nifti(data_root):
    lung = read_image(data_root / "images/itk_examples_data/RatLungSlice1.mha")
    assert lung.shape == (128, 128) and lung.data.max() > lung.data.min()
    with pytest.raises(InputError, match="3D volume"):
        read_image(data_root / "images/itk_examples_data/BrainProtonDensity3Slices.mha")
    three = read_image(data_root / "images/itk_examples_data/BrainProtonDensity3Slices.mha", slice_index=1)
    assert three.shape == (217, 181)
    anat = read_image(data_root / "images/nibabel_testdata/anatomical.nii", slice_index=12)
    assert anat.spacing == (2.0, 2.0)
