"""Fixtures for the registration tests: the bundled ITK brain slices and small synthetic images."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tests_paths import ITK_DIR


@pytest.fixture(scope="session")
def t1_slice():
    """BrainT1Slice.png, in register with the PD slice."""
    from topomatch.stages.registration.io import read_image

    return read_image(ITK_DIR / "BrainT1Slice.png")


@pytest.fixture
def blob_image():
    """A smooth, asymmetric 64 x 80 test image (two Gaussian blobs and a ramp), built in code."""
    from topomatch.stages.registration.image import Image

    rows, cols = np.mgrid[0:64, 0:80].astype(float)
    data = (100 * np.exp(-((cols - 30) ** 2 + (rows - 25) ** 2) / 120.0)
            + 60 * np.exp(-((cols - 52) ** 2 + (rows - 40) ** 2) / 60.0) + 0.2 * cols)
    return Image(data, name="blobs")


@pytest.fixture(scope="session")
def data_root() -> Path:
    """The external data root; the test is skipped when TOPOMATCH_DATA_ROOT is not set."""
    value = os.environ.get("TOPOMATCH_DATA_ROOT")
    if not value or not Path(value).is_dir():
        pytest.skip("needs the external data root (TOPOMATCH_DATA_ROOT)")
    return Path(value)
