"""Reading 3D volumes: geometry as SimpleITK reads it, DICOM series folders, and bad inputs named clearly."""

from __future__ import annotations

import numpy as np
import pytest

from tests_paths import ITK_DIR

sitk = pytest.importorskip("SimpleITK")

from topomatch.pipeline.errors import InputError  # noqa: E402


def _volume(shape=(10, 12, 14), spacing=(2.0, 2.0, 3.0), origin=(5.0, -3.0, 7.0), seed=0):
    rng = np.random.default_rng(seed)
    img = sitk.GetImageFromArray(rng.uniform(0, 100, shape).astype(np.float32))
    img.SetSpacing(spacing)
    img.SetOrigin(origin)
    img.SetDirection((1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0))
    return img


def write_dicom_series(image, folder, series_uid: str, *, first_instance: int = 1) -> None:
    """One file per slice with the tags a DICOM reader needs to stack them (SimpleITK's DicomSeriesFromArray recipe)."""
    from topomatch.stages.registration.volume_io import keep_locale

    with keep_locale():  # GDCM's writer leaves the process locale at "C"
        _write_dicom_series(image, folder, series_uid, first_instance)


def _write_dicom_series(image, folder, series_uid: str, first_instance: int) -> None:
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
    from topomatch.stages.registration.volume_io import read_volume

    path = ITK_DIR / "KmeansTest_T1UCharRaw.nii.gz"
    vol, img = read_volume(path), sitk.ReadImage(str(path))
    assert vol.size == img.GetSize() == (128, 128, 62) and vol.spacing == img.GetSpacing() == (2.0, 2.0, 3.0)
    assert vol.origin == img.GetOrigin()
    np.testing.assert_array_equal(vol.direction.ravel(), img.GetDirection())
    np.testing.assert_array_equal(vol.data, sitk.GetArrayFromImage(img))
    assert vol.name == "KmeansTest_T1UCharRaw"


@pytest.mark.parametrize("suffix", [".mha", ".nrrd", ".nii.gz"])
def test_formats_round_trip(tmp_path, suffix):
    from topomatch.stages.registration.volume_io import read_volume

    img = _volume()
    sitk.WriteImage(img, str(tmp_path / f"v{suffix}"))
    vol = read_volume(tmp_path / f"v{suffix}")
    np.testing.assert_allclose(vol.physical(np.array([[3.0, 4.0, 5.0]]))[0],
                               img.TransformIndexToPhysicalPoint((3, 4, 5)), atol=1e-4)
    np.testing.assert_allclose(vol.data, sitk.GetArrayFromImage(img), rtol=1e-6)


def test_dicom_series_folder_and_mixed_series(tmp_path):
    from topomatch.stages.registration.volume_io import read_volume

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

    from topomatch.stages.registration.volume_io import read_volume, read_volume_pair

    nib.save(nib.Nifti1Image(np.random.default_rng(0).normal(size=(6, 6, 6, 3)).astype(np.float32), np.eye(4)),
             tmp_path / "four.nii.gz")
    with pytest.raises(InputError, match=r"four.nii.gz: is a 4D image \(6 x 6 x 6 x 3: 3 volumes"):
        read_volume(tmp_path / "four.nii.gz")
    nib.save(nib.Nifti1Image(np.full((6, 6, 6), 7, dtype=np.int16), np.eye(4)), tmp_path / "flat.nii")
    with pytest.raises(InputError, match=r"flat.nii: image is constant"):
        read_volume(tmp_path / "flat.nii")
    sitk.WriteImage(_volume(), str(tmp_path / "ok.mha"))
    sitk.WriteImage(sitk.Cast(_volume()[:, :, 0], sitk.sitkUInt8), str(tmp_path / "flat2d.png"))
    with pytest.raises(InputError, match=r"flat2d.png: the moving image is 2D but the other input ok.mha is a 3D"):
        read_volume_pair(tmp_path / "ok.mha", tmp_path / "flat2d.png")
    with pytest.raises(InputError, match=r"missing.nii: file not found"):
        read_volume_pair(tmp_path / "ok.mha", tmp_path / "missing.nii")
