"""The wheel as ``pip install .`` builds it: one package, ``topomatch``, with the bundled data and configs,
working from any folder."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import zipfile

import pytest

from tests_paths import REPO_ROOT


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The wheel built from this checkout, as ``pip install .`` builds it."""
    out = tmp_path_factory.mktemp("wheel")
    source = out / "source"  # a copy: setuptools builds in the source tree (build/, *.egg-info)
    shutil.copytree(REPO_ROOT, source, ignore=shutil.ignore_patterns(
        ".git", ".venv", "runs", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache", ".ruff_cache"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out),
                    str(source)], check=True, capture_output=True, timeout=600)
    (built,) = out.glob("topomatch-*.whl")
    return built


@pytest.fixture(scope="module")
def installed(wheel):
    """The wheel, unpacked (what pip installs into site-packages)."""
    site = wheel.parent / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(site)
    return site


@pytest.fixture(scope="module")
def pip_installed(wheel):
    """The wheel installed by pip into a folder of its own, with its ``bin/topomatch`` command (the dependencies
    are the current environment's)."""
    target = wheel.parent / "target"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-index", "-q",
                    "--target", str(target), str(wheel)], check=True, capture_output=True, timeout=600)
    return target


def _env(site) -> dict[str, str]:
    """The environment of a user of the installed package: only ``site`` on the path, no data root."""
    env = {**os.environ, "PYTHONPATH": str(site)}
    env.pop("TOPOMATCH_DATA_ROOT", None)
    return env


def _python(site, code, cwd):
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd, env=_env(site),
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
            "p = topomatch.data_path('torus.off')\n"
            "assert str(p).startswith(os.environ['PYTHONPATH']), p\n"
            "print(topomatch.skeleton(topomatch.read_mesh(p)).cycle_rank)\n"
            "from topomatch.cli import main\n"
            "sys.exit(main(['run', 'configs/registration/demo.yaml', '--out', 'runs', '--no-progress']))\n")
    r = _python(installed, code, tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == "1"
    assert list((tmp_path / "runs").glob("registration-demo-*/index.html"))


@pytest.mark.slow
def test_the_wheel_declares_its_stages_as_entry_points(installed, tmp_path):
    """The wheel's metadata names each stage's module, so a lookup imports that module alone."""
    code = ("import os, sys\n"
            "from topomatch.pipeline.registry import declared, get_stage\n"
            "(ep,) = declared('stage')['register']\n"
            "assert str(ep.dist.locate_file('')).startswith(os.environ['PYTHONPATH']), ep.dist\n"
            "get_stage('register')\n"
            "print(len(declared('stage')), sorted({m.split('.')[2] for m in sys.modules if m.startswith('topomatch.stages.')}))")
    r = _python(installed, code, tmp_path)
    assert r.returncode == 0, r.stderr
    count, domains = r.stdout.split(" ", 1)
    assert int(count) >= 30 and domains.strip() == "['optimize', 'registration']"


def _blocks(doc: str, language: str) -> list[str]:
    """The fenced ``language`` code blocks of ``doc`` (a file of the repository)."""
    return re.findall(rf"^```{language}\n(.*?)^```", (REPO_ROOT / doc).read_text(), re.S | re.M)


def _commands(block: str) -> list[list[str]]:
    """The shell commands of a bash block: continuation lines joined, comments dropped."""
    return [shlex.split(line, comments=True) for line in block.replace("\\\n", " ").splitlines() if line.strip()]


@pytest.mark.slow
def test_the_docs_examples_run_from_an_empty_folder_with_the_installed_wheel(pip_installed, tmp_path):
    """The README's command-line and Python examples on bundled data and docs/api.md's Python tour, as the docs
    write them (``/tmp/`` moved into a temporary folder), run from an empty folder where only the installed wheel
    is importable: this breaks when the docs drift or name files of the checkout."""
    work = tmp_path / "work"
    work.mkdir()

    def run(argv, what):
        r = subprocess.run(argv, capture_output=True, text=True, cwd=work, env=_env(pip_installed), timeout=300)
        assert r.returncode == 0 and "Traceback" not in r.stderr, f"{what}\n{r.stderr[-3000:]}"
        return r.stdout

    # the installed package, not the checkout (which the environment may also have installed, editable)
    where = "import os, topomatch; assert topomatch.__file__.startswith(os.environ['PYTHONPATH']), topomatch.__file__\n"

    # the README's commands on bundled data ("bundled:NAME"), in their order (query and evaluate need the index)
    (block,) = [b for b in _blocks("README.md", "bash") if "bundled:" in b]
    commands = [c for c in _commands(block.replace("/tmp/", f"{tmp_path}/")) if c[1] != "run"]  # run: a 200 s config
    assert sum("bundled:" in " ".join(c) for c in commands) >= 7
    assert all(c[0] == ".venv/bin/topomatch" for c in commands)
    for command in commands:
        out = run([str(pip_installed / "bin" / "topomatch"), *command[1:]], shlex.join(command))
        if command[1] == "skeleton" and "--json" in command:
            assert json.loads(out)["mesh"].startswith(str(pip_installed))  # the installed data, not data/

    # the Python examples: the README's, then docs/api.md's tour (its blocks in order, one script)
    for doc in ("README.md", "docs/api.md"):
        blocks = [b for b in _blocks(doc, "python") if doc != "README.md" or "data_path(" in b]
        assert blocks and "data_path(" in blocks[0] and "data/meshes" not in "".join(blocks)
        run([sys.executable, "-c", where + "".join(blocks).replace("/tmp/", f"{tmp_path}/")], doc)
    assert (tmp_path / "shapes.db").is_file() and (work / "shapes.topomatch.npz").is_file()
    assert list((work / "runs").glob("demo-*/index.html"))
