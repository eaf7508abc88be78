"""The wheel as ``pip install .`` builds it: one package, ``topomatch``, with the bundled data and configs,
working from any folder."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile

import pytest

from tests_paths import REPO_ROOT


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The wheel built from this checkout, unpacked (what pip installs into site-packages)."""
    out = tmp_path_factory.mktemp("wheel")
    source = out / "source"  # a copy: setuptools builds in the source tree (build/, *.egg-info)
    shutil.copytree(REPO_ROOT, source, ignore=shutil.ignore_patterns(
        ".git", ".venv", "runs", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache", ".ruff_cache"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out),
                    str(source)], check=True, capture_output=True, timeout=600)
    (wheel,) = out.glob("topomatch-*.whl")
    site = out / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(site)
    return site


def _python(site, code, cwd):
    env = {**os.environ, "PYTHONPATH": str(site)}
    env.pop("TOPOMATCH_DATA_ROOT", None)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=600)


@pytest.mark.slow
def test_the_wheel_is_one_package_with_its_data(installed):
    tops = {p.name for p in installed.iterdir() if not p.name.endswith(".dist-info")}
    assert tops == {"topomatch"}  # no top-level 'pipeline' or 'stages'
    pkg = installed / "topomatch"
    for rel in ("pipeline/contract.py", "stages/spectral/eigen/__init__.py", "cli/__init__.py",
                "data/meshes/torus.off", "data/meshes/labels.csv", "data/images/itk/registration_pairs.csv",
                "data/ATTRIBUTION.md", "configs/demo.yaml", "configs/retrieval/demo.yaml"):
        assert (pkg / rel).is_file(), rel


@pytest.mark.slow
def test_the_installed_package_works_from_any_folder(installed, tmp_path):
    code = ("import topomatch, os, sys\n"
            "assert topomatch.__file__.startswith(os.environ['PYTHONPATH'])\n"
            "p = os.path.join(os.path.dirname(topomatch.__file__), 'data', 'meshes', 'torus.off')\n"
            "print(topomatch.skeleton(topomatch.read_mesh(p)).cycle_rank)\n"
            "from topomatch.cli import main\n"
            "sys.exit(main(['run', 'configs/registration/demo.yaml', '--out', 'runs', '--no-progress']))\n")
    r = _python(installed, code, tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == "1"
    assert list((tmp_path / "runs").glob("registration-demo-*/index.html"))
