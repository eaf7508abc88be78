"""Paths of the repository's test data, importable from any test module."""

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
BUNDLED_MESHES = REPO_ROOT / "data" / "meshes"
ITK_DIR = REPO_ROOT / "data" / "images" / "itk"
