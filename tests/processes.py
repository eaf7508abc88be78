"""Processes a test started, found by a tag in their environment (``TOPOMATCH_TEST_TAG``), so that a test can
check that none outlived it."""

from __future__ import annotations

from pathlib import Path

TAG_ENV = "TOPOMATCH_TEST_TAG"


def tagged_processes(tag: str) -> list[int]:
    """Pids of the live processes whose environment holds ``TOPOMATCH_TEST_TAG=tag``."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            env = (entry / "environ").read_bytes()
            state = (entry / "stat").read_text().split()[2]
        except OSError:
            continue
        if f"{TAG_ENV}={tag}".encode() in env and state != "Z":
            found.append(int(entry.name))
    return found
