"""topomatch: topological shape skeletons, shape matching and retrieval, and entropic image registration.

The installed package joins the repository's top-level folders under one import name:
``topomatch.pipeline`` is ``pipeline/`` (the engine), ``topomatch.stages`` is ``stages/`` (the
science), ``topomatch.data`` and ``topomatch.configs`` are the bundled data and experiment configs.
"""

from __future__ import annotations

from pathlib import Path

__version__ = "0.1.0"

# A source checkout without an install (or an editable one): the engine, the stages, the data and
# the configs are this folder's siblings, so they are looked up there too.
if not (Path(__file__).resolve().parent / "pipeline").is_dir():
    __path__.append(str(Path(__file__).resolve().parent.parent))  # noqa: F821 (package __path__)
