"""``topomatch register`` as a user runs it: JSON, text, output files, flags and bad inputs."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image as PILImage

from cli_schema import check
from topomatch.cli import main
from tests_paths import REPO_ROOT

CONFIGS = REPO_ROOT / "configs" / "registration"


def register_cli(capsys, *args):
    code = main(["register", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_json_recovers_the_itk_translation(capsys, itk_dir):
    code, out, _ = register_cli(capsys, itk_dir / "BrainProtonDensitySliceBorder20.png",
                                itk_dir / "BrainProtonDensitySliceShifted13x17y.png", "--json")
    assert code == 0
    res = json.loads(out)
    assert res["tx"] == pytest.approx(13, abs=0.1) and res["ty"] == pytest.approx(17, abs=0.1)
    assert abs(res["angle"]) < 0.1 and res["ok"] and res["metric"] == "jt"
    assert {"objective", "iterations", "seconds", "center", "convention", "parameters", "names", "matrix"} <= set(res)
    assert res["dimension"] == 2 and res["names"] == ["angle", "tx", "ty"] and len(res["matrix"]) == 3
    assert res["parameters"][1:] == pytest.approx([res["tx"], res["ty"]], abs=1e-6)


def test_cli_text_and_outputs(capsys, itk_dir, tmp_path):
    code, out, _ = register_cli(capsys, itk_dir / "BrainT1Slice.png", itk_dir / "BrainProtonDensitySlice.png",
                                "--metric", "mi", "--out", tmp_path / "out")
    assert code == 0
    for key in ("tx:", "ty:", "angle:", "objective:", "iterations:", "seconds:"):
        assert key in out
    resampled = np.asarray(PILImage.open(tmp_path / "out" / "moving_resampled.png"))
    assert resampled.shape == (217, 181) and resampled.dtype == np.uint8
    assert np.asarray(PILImage.open(tmp_path / "out" / "moving_resampled.tif")).dtype == np.float32
    assert (tmp_path / "out" / "overlay.png").stat().st_size > 20_000
    saved = json.loads((tmp_path / "out" / "registration.json").read_text())
    assert len(saved["history"]["theta"]) == saved["iterations"]


def test_cli_flags_a_misalignment_outside_the_capture_range(capsys, pd_slice, tmp_path):
    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.transform import RigidTransform

    moving = moved(pd_slice, RigidTransform.euler2d(0, 0, 150, pd_slice.center))
    path = tmp_path / "upside_down.png"
    PILImage.fromarray(np.clip(moving.data, 0, 255).astype(np.uint8)).save(path)
    PILImage.fromarray(pd_slice.data.astype(np.uint8)).save(tmp_path / "fixed.png")
    code, out, err = register_cli(capsys, tmp_path / "fixed.png", path, "--json")
    assert code == 1
    assert json.loads(out)["ok"] is False
    assert "registration flagged" in err and json.loads(out)["flags"]


def test_cli_bad_inputs(capsys, itk_dir, tmp_path):
    png = itk_dir / "BrainT1Slice.png"
    code, _, err = register_cli(capsys, png, tmp_path / "missing.png")
    assert code == 1 and "missing.png: file not found" in err
    code, _, err = register_cli(capsys, png, itk_dir / "KmeansTest_T1UCharRaw.nii.gz")
    assert code == 1 and "KmeansTest_T1UCharRaw.nii.gz" in err and "different dimensionality" in err
    code, out, _ = register_cli(capsys, itk_dir / "KmeansTest_T1UCharRaw.nii.gz", itk_dir / "KmeansTest_T1UCharRaw.nii.gz",
                                "--fixed-slice", "30", "--moving-slice", "31", "--json")
    assert code == 0 and json.loads(out)["ok"]
    nan = np.full((40, 40), 5.0, np.float32)
    nan[10:20, 10:20] = 50
    nan[0, 0] = np.nan
    PILImage.fromarray(nan).save(tmp_path / "nan.tif")
    code, _, err = register_cli(capsys, png, tmp_path / "nan.tif")
    assert code == 1 and "nan.tif: 1 of 1600 pixels are NaN" in err
    PILImage.fromarray(np.zeros((40, 40), np.uint8)).save(tmp_path / "black.png")
    code, _, err = register_cli(capsys, tmp_path / "black.png", png)
    assert code == 1 and "black.png: image is constant" in err
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 20)
    code, _, err = register_cli(capsys, png, tmp_path / "broken.png")
    assert code == 1 and "broken.png: cannot read image" in err
    assert "Traceback" not in err


@pytest.fixture(scope="module")
def volume_pair(tmp_path_factory):
    """A small fixed volume (KmeansTest at 4 x 4 x 3 mm, .nii.gz) and a moved, T2-like, NRRD copy; the true T."""
    import SimpleITK as sitk

    from topomatch.stages.registration.io import read_volume, to_sitk
    from topomatch.stages.registration.misalign import make_case

    folder = tmp_path_factory.mktemp("volumes")
    case = make_case(read_volume(REPO_ROOT / "data/images/itk/KmeansTest_T1UCharRaw.nii.gz").shrink((2, 2, 1)), 3,
                     seed=21, multimodal=True, crop=False)
    sitk.WriteImage(to_sitk(case.fixed), str(folder / "fixed.nii.gz"))
    sitk.WriteImage(sitk.Cast(to_sitk(case.moving), sitk.sitkInt16), str(folder / "moving.nrrd"))
    return folder / "fixed.nii.gz", folder / "moving.nrrd", case


def test_cli_3d_json_matrix_tfm_and_resampled_geometry(capsys, volume_pair, tmp_path):
    import SimpleITK as sitk

    from topomatch.stages.registration.evaluate import tre_points
    from topomatch.stages.registration.transform import RigidTransform, target_registration_error

    fixed, moving, case = volume_pair
    code, out, _ = register_cli(capsys, fixed, moving, "--json", "--out", tmp_path / "out")
    assert code == 0
    res = json.loads(out)
    check(res, "register")  # the documented --json schema covers 3D results too
    assert res["dimension"] == 3 and res["ok"] and len(res["parameters"]) == 6
    estimate = RigidTransform(res["parameters"], res["center"])
    assert target_registration_error(estimate, case.truth, tre_points(case.fixed)).mean() < 1.0
    np.testing.assert_allclose(res["center"], case.fixed.center, atol=1e-6)
    # the matrix is SimpleITK's Euler3DTransform of the printed parameters, and what transform.tfm holds
    e = sitk.Euler3DTransform(res["center"], *res["parameters"][:3], res["parameters"][3:])
    pts = np.array([[10.0, -20.0, 30.0], [0.0, 0.0, 0.0]])
    M = np.asarray(res["matrix"])
    np.testing.assert_allclose(pts @ M[:3, :3].T + M[:3, 3], [e.TransformPoint(tuple(p)) for p in pts], atol=1e-6)
    read = sitk.ReadTransform(str(tmp_path / "out" / "transform.tfm"))
    np.testing.assert_allclose([read.TransformPoint(tuple(p)) for p in pts], [e.TransformPoint(tuple(p)) for p in pts],
                               atol=1e-6)
    resampled, f = sitk.ReadImage(str(tmp_path / "out" / "moving_resampled.nrrd")), sitk.ReadImage(str(fixed))
    assert resampled.GetSize() == f.GetSize() and resampled.GetPixelID() == sitk.sitkInt16
    np.testing.assert_allclose(resampled.GetSpacing(), f.GetSpacing())
    np.testing.assert_allclose(resampled.GetOrigin(), f.GetOrigin(), atol=1e-6)
    np.testing.assert_allclose(resampled.GetDirection(), f.GetDirection())
    assert (tmp_path / "out" / "overlay.png").stat().st_size > 20_000
    assert json.loads((tmp_path / "out" / "registration.json").read_text())["matrix"] == res["matrix"]


@pytest.mark.parametrize("storage", ["flipped", "turned"])
def test_cli_3d_moving_stored_on_another_grid(capsys, volume_pair, tmp_path, storage):
    """The moving volume stored otherwise, its content where it was in physical space: with its first axis reversed (a
    direction of determinant -1), the same samples, so the plain file's result within 0.05 mm; or resampled by SimpleITK
    (cubic B-spline) onto a grid turned by 25 degrees about z and half as large again (an oblique header, an empty
    margin), a passed result within 1 mm of the truth. (Linear resampling of these 4 mm voxels onto the turned grid
    blurs them unevenly: the result, 0.6 mm off, is then refused by `stability`.)"""
    import SimpleITK as sitk

    from topomatch.stages.registration.evaluate import tre_points
    from topomatch.stages.registration.transform import RigidTransform, target_registration_error

    fixed, moving, case = volume_pair
    image = sitk.ReadImage(str(moving), sitk.sitkFloat32)
    if storage == "flipped":
        stored = sitk.GetImageFromArray(np.ascontiguousarray(sitk.GetArrayFromImage(image)[:, :, ::-1]))
        stored.SetSpacing(image.GetSpacing())
        stored.SetDirection(tuple((np.asarray(image.GetDirection()).reshape(3, 3) * [-1.0, 1.0, 1.0]).ravel()))
        stored.SetOrigin(image.TransformIndexToPhysicalPoint((image.GetSize()[0] - 1, 0, 0)))
    else:
        a = math.radians(25.0)
        turn = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        size = [int(1.5 * n) for n in image.GetSize()]
        center = np.asarray(image.TransformContinuousIndexToPhysicalPoint([(n - 1) / 2 for n in image.GetSize()]))
        grid = sitk.Image(size, sitk.sitkFloat32)
        grid.SetSpacing(image.GetSpacing())
        grid.SetDirection(tuple(turn.ravel()))
        grid.SetOrigin(tuple(center - turn @ ((np.asarray(size) - 1) / 2 * np.asarray(image.GetSpacing()))))
        stored = sitk.Resample(image, grid, sitk.Transform(), sitk.sitkBSpline, 0.0)
    sitk.WriteImage(stored, str(tmp_path / "moving_stored.nii.gz"))
    results = []
    for path in (moving, tmp_path / "moving_stored.nii.gz"):
        code, out, _ = register_cli(capsys, fixed, path, "--json")
        res = json.loads(out)
        assert code == 0 and res["ok"], res.get("reason")
        results.append(RigidTransform(res["parameters"], res["center"]))
    points = tre_points(case.fixed)
    assert target_registration_error(results[1], case.truth, points).mean() < 1.0
    if storage == "flipped":
        assert target_registration_error(results[1], results[0], points).mean() < 0.05


def test_cli_3d_bad_inputs(capsys, volume_pair, itk_dir, tmp_path):
    import nibabel as nib

    fixed, _, _ = volume_pair
    code, _, err = register_cli(capsys, fixed, itk_dir / "BrainT1Slice.png")
    assert code == 1 and "fixed.nii.gz" in err and "BrainT1Slice.png is 2D" in err and "different dimensionality" in err
    nib.save(nib.Nifti1Image(np.random.default_rng(0).normal(size=(8, 8, 8, 2)).astype(np.float32), np.eye(4)),
             tmp_path / "series.nii.gz")
    code, _, err = register_cli(capsys, fixed, tmp_path / "series.nii.gz")
    assert code == 1 and "series.nii.gz: is a 4D image" in err
    nib.save(nib.Nifti1Image(np.zeros((8, 8, 8), np.int16), np.eye(4)), tmp_path / "zero.nii")
    code, _, err = register_cli(capsys, tmp_path / "zero.nii", fixed)
    assert code == 1 and "zero.nii: image is constant" in err
    assert "Traceback" not in err


def test_2d_outputs_include_an_itk_transform_and_the_input_format(capsys, itk_dir, tmp_path):
    """transform.tfm resamples the moving image with SimpleITK as our own resampling does; a NIfTI moving
    image also gives a NIfTI resampled image with the fixed spacing."""
    import nibabel as nib
    import SimpleITK as sitk

    fixed_png = itk_dir / "BrainProtonDensitySliceBorder20.png"
    moving_png = itk_dir / "BrainProtonDensitySliceR10X13Y17.png"
    code, out, _ = register_cli(capsys, fixed_png, moving_png, "--json", "--out", tmp_path / "png")
    assert code == 0
    files = json.loads(out)["files"]
    assert str(tmp_path / "png" / "transform.tfm") in files
    T = sitk.ReadTransform(str(tmp_path / "png" / "transform.tfm"))
    fixed, moving = sitk.ReadImage(str(fixed_png), sitk.sitkFloat32), sitk.ReadImage(str(moving_png), sitk.sitkFloat32)
    by_sitk = sitk.GetArrayFromImage(sitk.Resample(moving, fixed, T, sitk.sitkLinear, 0.0))
    ours = np.asarray(PILImage.open(tmp_path / "png" / "moving_resampled.tif"))
    inside = by_sitk > 0
    assert inside.mean() > 0.5 and np.abs(by_sitk[inside] - ours[inside]).mean() < 1.0  # grey levels of 0..255
    # NIfTI input: the resampled image comes back as NIfTI too. Written with the PNG's geometry (origin 0, unit
    # spacing, ITK's identity direction: in NIfTI's RAS frame, x and y flipped); with an identity RAS affine the
    # image would be, physically, the PNG turned by 180 degrees
    data = np.asarray(PILImage.open(moving_png), dtype=np.float32)
    nib.save(nib.Nifti1Image(data.T[:, :, None], np.diag([-1.0, -1.0, 1.0, 1.0])), tmp_path / "moving.nii.gz")
    code, out, _ = register_cli(capsys, fixed_png, tmp_path / "moving.nii.gz", "--json", "--out", tmp_path / "nii")
    assert code == 0 and (tmp_path / "nii" / "moving_resampled.nii.gz").is_file()
    back = sitk.GetArrayFromImage(sitk.ReadImage(str(tmp_path / "nii" / "moving_resampled.nii.gz")))
    assert back.shape == np.asarray(PILImage.open(fixed_png)).shape


def test_cli_json_reports_the_order_used_on_an_outline_only_pair(capsys, pd_slice, tmp_path):
    """A silhouette of the PD slice (a NIfTI file, uniform inside) moved by a known T: ``topomatch register
    --json`` reports ``alpha`` 1 (``metric.outline_alpha``), the order it used, and recovers T; an ordinary pair
    reports the metric's own 2."""
    import SimpleITK as sitk

    from topomatch.stages.registration.misalign import moved
    from topomatch.stages.registration.structure import object_mask
    from topomatch.stages.registration.transform import RigidTransform

    silhouette = pd_slice.with_data(np.where(object_mask(pd_slice), 100.0, 0.0))
    path = tmp_path / "silhouette.nii.gz"
    sitk.WriteImage(sitk.GetImageFromArray(moved(silhouette, RigidTransform.euler2d(8.0, 5.0, -4.0, pd_slice.center))
                                           .data.astype(np.float32)), str(path))
    code, out, _ = register_cli(capsys, pd_slice.source, path, "--json")
    data = json.loads(out)
    assert code == 0 and data["alpha"] == 1.0 and data["metric"] == "jt"
    assert abs(data["angle"] + 4.0) < 0.3 and abs(data["tx"] - 8.0) < 0.5 and abs(data["ty"] - 5.0) < 0.5
    code, out, _ = register_cli(capsys, pd_slice.source, pd_slice.source, "--json")
    assert json.loads(out)["alpha"] == 2.0


def test_cli_set_reaches_any_parameter_and_names_the_wrong_ones(capsys, itk_dir):
    """``--set`` sets a nested register parameter (a flatness threshold no registration meets: flagged, exit 1;
    the measure's order, by the stage's name: reported), a misspelt path lists the fields next to it, a rejected
    value names the bound, a malformed item says what it expects: exit 2, nothing run."""
    pd = itk_dir / "BrainProtonDensitySliceBorder20.png"
    shifted = itk_dir / "BrainProtonDensitySliceShifted13x17y.png"
    code, out, _ = register_cli(capsys, pd, shifted, "--json", "--set", "check.min_flatness=0.99")
    res = json.loads(out)  # the flag and the measure it compared, in the JSON
    assert code == 1 and "flatness" in res["flags"] and 0 < res["measures"]["flatness"] < 0.99
    code, out, _ = register_cli(capsys, pd, shifted, "--json", "--set", "register.metric.alpha=1.5")
    assert code == 0 and json.loads(out)["alpha"] == 1.5
    for item, words in [("check.min_structur=0", "those of register.check: search"),
                        ("check.min_residual=-1", "greater than or equal to 0"),
                        ("load_pair.fixed_slice=x", "valid integer"),
                        ("nothing", "expected param=value"),
                        ("check.min_flatness=[1,2", "--set check.min_flatness: not valid YAML: expected ',' or ']', "
                                                    "but got '<stream end>' (line 1, column 5)\n")]:
        code, out, err = register_cli(capsys, pd, shifted, "--set", item)
        assert code == 2 and words in err and out == ""


def test_a_file_that_cannot_be_written_loses_no_result(capsys, itk_dir, tmp_path):
    """A folder where ``transform.tfm`` should go: the result is printed, every other file is written, no temporary
    file is left, and the error names the path in the way (exit 1)."""
    out = tmp_path / "out"
    (out / "transform.tfm").mkdir(parents=True)
    code, stdout, err = register_cli(capsys, itk_dir / "BrainProtonDensitySlice.png",
                                     itk_dir / "BrainProtonDensitySliceR10X13Y17.png", "--out", out, "--json")
    assert code == 1 and "transform.tfm: is a folder, not a file" in err
    result = json.loads(stdout)  # the JSON says what was not written, so a script reading it knows why the exit is 1
    assert result["angles"][0] == pytest.approx(10.0, abs=0.1) and result["ok"]
    assert "transform.tfm: is a folder, not a file" in result["unwritten"]
    assert {Path(p).name for p in result["files"]} == {"moving_resampled.png", "moving_resampled.tif", "overlay.png",
                                                       "registration.json"}  # what was written, the folder left out
    check(result, "register")
    assert {p.name for p in out.iterdir()} == {"moving_resampled.png", "moving_resampled.tif", "overlay.png",
                                               "registration.json", "transform.tfm"}


@pytest.mark.parametrize("d", [2, 3])
def test_moving_resampled_is_simpleitks_resampling_by_the_written_transform(capsys, itk_dir, tmp_path, d):
    """What the ``--out`` docs promise: ``sitk.Resample(moving, fixed, sitk.ReadTransform('transform.tfm'))``
    (linear, the moving minimum outside) is ``moving_resampled``, to float32 rounding, edges included."""
    import SimpleITK as sitk

    if d == 2:
        fixed, moving = itk_dir / "BrainProtonDensitySlice.png", itk_dir / "BrainProtonDensitySliceR10X13Y17.png"
        written = tmp_path / "out" / "moving_resampled.tif"
    else:
        volume = sitk.ReadImage(str(itk_dir / "KmeansTest_T1UCharRaw.nii.gz"), sitk.sitkFloat32)[::2, ::2, :]
        t = sitk.Euler3DTransform(volume.TransformContinuousIndexToPhysicalPoint([s / 2 for s in volume.GetSize()]),
                                  0.05, -0.04, 0.08, (3.0, -2.0, 4.0))
        fixed, moving = tmp_path / "fixed.nii.gz", tmp_path / "moving.nii.gz"
        sitk.WriteImage(volume, str(fixed))
        sitk.WriteImage(sitk.Resample(volume, volume, t.GetInverse(), sitk.sitkLinear, 0.0), str(moving))
        written = tmp_path / "out" / "moving_resampled.nii.gz"
    register_cli(capsys, fixed, moving, "--out", tmp_path / "out")
    F, M = sitk.ReadImage(str(fixed), sitk.sitkFloat32), sitk.ReadImage(str(moving), sitk.sitkFloat32)
    if d == 2:
        F, M = (sitk.Extract(X, X.GetSize()[:2] + (0,), (0, 0, 0)) if X.GetDimension() == 3 else X for X in (F, M))
    tfm = sitk.ReadTransform(str(tmp_path / "out" / "transform.tfm"))
    minimum = float(sitk.GetArrayViewFromImage(M).min())
    expected = sitk.GetArrayFromImage(sitk.Resample(M, F, tfm, sitk.sitkLinear, minimum, sitk.sitkFloat32))
    np.testing.assert_allclose(sitk.GetArrayFromImage(sitk.ReadImage(str(written), sitk.sitkFloat32)), expected,
                               atol=1e-3 * float(expected.max()))


def test_verbose_lists_the_outputs_and_debug_stays_ours(capsys, itk_dir, tmp_path):
    """``-v`` names the registration's time and every file written; ``-vv`` adds topomatch's debug logging, not every
    library's (matplotlib's font search filled 190 lines)."""
    args = (itk_dir / "BrainProtonDensitySlice.png", itk_dir / "BrainProtonDensitySliceR10X13Y17.png", "--out",
            tmp_path / "out")
    _, _, err = register_cli(capsys, *args, "-v")
    assert "register:" in err and all(f"output: {tmp_path / 'out' / name}" in err for name in (
        "transform.tfm", "overlay.png", "registration.json"))
    import subprocess
    import sys

    # a process of its own: pytest's log capture would hide what the root logger lets through
    err = subprocess.run([sys.executable, "-m", "topomatch", "register", *map(str, args), "-vv"], capture_output=True,
                         text=True, cwd=tmp_path).stderr
    assert "output:" in err and "matplotlib" not in err and "PIL" not in err, err[-2000:]


def test_a_flagged_pair_of_a_png_and_a_nifti_names_their_conventions(capsys, itk_dir, tmp_path):
    """The same pixels as a NIfTI with nibabel's identity affine (RAS: a 180-degree turn from the PNG's pixel frame)
    against the PNG: flagged, and the reason says the two formats place pixels differently."""
    nib = pytest.importorskip("nibabel")
    png = itk_dir / "BrainProtonDensitySlice.png"
    data = np.asarray(PILImage.open(png), dtype=np.float32)
    nib.save(nib.Nifti1Image(data.T[:, :, None], np.eye(4)), tmp_path / "same.nii.gz")
    code, _, err = register_cli(capsys, tmp_path / "same.nii.gz", png)
    assert code == 1 and "in pixel units with rows down" in err and "180 degrees" in err


def test_a_16_bit_png_gives_a_16_bit_resampled_png(capsys, itk_dir, tmp_path):
    """A 16-bit moving PNG (values up to 60,000): ``moving_resampled.png`` keeps 16 bits and its values are the float
    ``.tif``'s, rounded (it used to be rescaled to 8 bits)."""
    fixed = np.asarray(PILImage.open(itk_dir / "BrainProtonDensitySlice.png"), dtype=np.float64)
    moving = np.asarray(PILImage.open(itk_dir / "BrainProtonDensitySliceR10X13Y17.png"), dtype=np.float64)
    for name, data in (("fixed16.png", fixed), ("moving16.png", moving)):
        PILImage.fromarray(np.round(data * 60000 / 255).astype(np.uint16)).save(tmp_path / name)
    code, _, _ = register_cli(capsys, tmp_path / "fixed16.png", tmp_path / "moving16.png", "--out", tmp_path / "out")
    png = np.asarray(PILImage.open(tmp_path / "out" / "moving_resampled.png"))
    tif = np.asarray(PILImage.open(tmp_path / "out" / "moving_resampled.tif"))
    assert code == 0 and png.dtype == np.uint16 and png.max() > 255
    np.testing.assert_allclose(png, tif, atol=1.0)  # the .tif holds float32: a half may round the other way
