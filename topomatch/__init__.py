"""topomatch: topological shape skeletons, shape matching and retrieval, and entropic image registration.

The Python API (the same operations, options and defaults as the command line)::

    import topomatch
    mesh = topomatch.read_mesh("hand.obj.gz")                   # or a bundled one: topomatch.data_path("torus.off")
    sk = topomatch.skeleton(mesh, function="fiedler")          # sk.n_endpoints, sk.graph, sk.to_dict()
    topomatch.match("cat.obj", "dog.obj").dissimilarity
    topomatch.index(["meshes/"], "shapes.db")                   # the best method by default
    topomatch.open_index("shapes.db").query("cat.obj", k=5).results
    reg = topomatch.register("fixed.png", "moving.png")         # reg.parameters, reg.matrix, reg.ok (2D: reg.tx ...)
    reg = topomatch.register("fixed.nii.gz", "moving.nrrd")     # the same for volumes (six parameters)
    topomatch.run_config("configs/demo.yaml").run_dir

The names are loaded on first use, so ``import topomatch`` is cheap. The installed package joins
the repository's top-level folders under one import name: ``topomatch.pipeline`` is ``pipeline/``
(the engine), ``topomatch.stages`` is ``stages/`` (the science), ``topomatch.data`` and
``topomatch.configs`` are the bundled data and experiment configs.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

__version__ = "0.1.0"

# A source checkout without an install (or an editable one): the engine, the stages, the data and
# the configs are this folder's siblings, so they are looked up there too.
if not (Path(__file__).resolve().parent / "pipeline").is_dir():
    __path__.append(str(Path(__file__).resolve().parent.parent))  # noqa: F821 (package __path__)

#: Public name -> the module that defines it.
_API = {
    "read_mesh": "topomatch.meshes", "Mesh": "topomatch.meshes",
    "skeleton": "topomatch.skeletons", "Skeleton": "topomatch.skeletons",
    "write_skeleton_files": "topomatch.skeletons",
    "match": "topomatch.retrieval", "MatchResult": "topomatch.retrieval",
    "index": "topomatch.retrieval", "IndexReport": "topomatch.retrieval",
    "open_index": "topomatch.retrieval", "Collection": "topomatch.retrieval",
    "QueryResult": "topomatch.retrieval", "Evaluation": "topomatch.retrieval",
    "read_image": "topomatch.registration", "register": "topomatch.registration",
    "RegistrationOutcome": "topomatch.registration", "write_registration_files": "topomatch.registration",
    "read_volume": "topomatch.registration", "Image": "topomatch.registration",
    "run_config": "topomatch.experiments", "load_config": "topomatch.experiments",
    "bundled_configs": "topomatch.experiments", "data_path": "topomatch.pipeline.paths",
    "METHODS": "topomatch.stages.retrieval.catalogue",
    "TopomatchError": "topomatch.pipeline.errors", "InputError": "topomatch.pipeline.errors",
    "ConfigError": "topomatch.pipeline.errors", "StageError": "topomatch.pipeline.errors",
}

__all__ = sorted(_API) + ["__version__"]


def __getattr__(name: str) -> Any:
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'topomatch' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
