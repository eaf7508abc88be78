"""Headless Chromium for the tests of the run pages' interactive views (Debian package ``chromium``,
installed in CI by ``scripts/install-system-deps.sh --browser``; the tests skip without it)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
         "--use-angle=swiftshader", "--virtual-time-budget=20000", "--window-size=1400,2400"]

needs_chromium = pytest.mark.skipif(chromium() is None, reason="no chromium (Debian package 'chromium'; installed "
                                                               "in CI by scripts/install-system-deps.sh --browser)")


def dump_dom(page: Path) -> str:
    """The DOM of a local page after its scripts ran."""
    return subprocess.run([chromium(), *FLAGS, "--dump-dom", page.resolve().as_uri()], capture_output=True, text=True,
                          timeout=240).stdout


def screenshot(page: Path, name: str, workdir: Path) -> Path:
    """A PNG of a local page in ``$TOPOMATCH_ARTEFACTS`` (or ``workdir``), kept as a test artefact."""
    # absolute: Chromium runs in workdir, and make test gives a folder relative to the repository
    shot = Path(os.environ.get("TOPOMATCH_ARTEFACTS") or workdir).resolve() / name
    shot.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([chromium(), *FLAGS, f"--screenshot={shot}", page.resolve().as_uri()], capture_output=True,
                   timeout=240, cwd=workdir)
    return shot
