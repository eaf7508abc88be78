"""The ``meshes`` input kind: ``inputs: {meshes: [templates]}``, one unit per mesh file (state ``path``, read by
the ``load`` stage)."""

from __future__ import annotations

from topomatch.pipeline.contract import InputFiles, InputUnit, input_kind


@input_kind("meshes", schema=list[str], provides=("path",))
def meshes(templates: list[str], files: InputFiles) -> list[InputUnit]:
    """Mesh files, as path templates ({bundled}, {data_root}, globs): one input per file."""
    return files.each(templates, "inputs.meshes")
