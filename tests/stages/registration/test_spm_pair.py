"""A real pair registered by another lab's tools, with its transform written down: nibabel's test data.

nibabel's ``tests/data/make_moved_anat.py`` gives ``anatomical.nii`` (33 x 41 x 25, 2 mm) the affine
``E @ A`` with ``E = from_matvec(euler2mat(0.1, 0.2, 0.3), [3, 4, 5])`` (RAS mm), and its ``to_canonical.m`` has SPM
resample that moved image onto a 4 mm grid of another orientation (``reoriented_anat_moved.nii``, 21 x 26 x 22).
So the moving image at world point ``y`` is the anatomical image at ``E^-1 y``: ``fixed(p) ~ moving(T(p))`` with
``T = E``, which in ITK's LPS coordinates is ``F E F``, ``F = diag(-1, -1, 1)``. The registration reads both files
as a user does (``topomatch.register``, the defaults), across resolution, orientation and SPM's resampling.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

nib = pytest.importorskip("nibabel")
from nibabel.affines import from_matvec  # noqa: E402
from nibabel.eulerangles import euler2mat  # noqa: E402

import topomatch  # noqa: E402

DATA = Path(nib.__file__).parent / "tests" / "data"
FIXED, MOVING = DATA / "anatomical.nii", DATA / "reoriented_anat_moved.nii"
pytestmark = pytest.mark.skipif(not (FIXED.is_file() and MOVING.is_file()),
                                reason="this nibabel installation has no test data")


def truth_lps() -> np.ndarray:
    """``F E F``: make_moved_anat.py's world transform in LPS, (4, 4)."""
    flip = np.diag([-1.0, -1.0, 1.0, 1.0])
    return flip @ from_matvec(euler2mat(0.1, 0.2, 0.3), [3, 4, 5]) @ flip


def brain_points(path: Path) -> np.ndarray:
    """LPS mm of the image's voxels above its median (the head), homogeneous, (4, n)."""
    img = nib.load(path)
    data = np.asanyarray(img.dataobj)
    index = np.argwhere(data > np.median(data))
    return np.diag([-1.0, -1.0, 1.0, 1.0]) @ img.affine @ np.c_[index, np.ones(len(index))].T


@pytest.mark.parametrize("metric", ["jt", "mi"])
@pytest.mark.parametrize("swapped", [False, True])
def test_spm_resampled_pair_recovers_nibabels_transform(metric, swapped):
    fixed, moving = (MOVING, FIXED) if swapped else (FIXED, MOVING)
    outcome = topomatch.register(fixed, moving, metric=metric)
    truth = np.linalg.inv(truth_lps()) if swapped else truth_lps()
    points = brain_points(fixed)
    tre = np.linalg.norm((np.asarray(outcome.matrix) @ points - truth @ points)[:3], axis=0)
    assert tre.mean() < 1.0, (tre.mean(), outcome.reason)  # the corpus's "correct": within a millimetre
    assert outcome.ok, outcome.reason
