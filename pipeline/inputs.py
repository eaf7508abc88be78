"""A config's inputs -> :class:`InputUnit` objects: files for state entries and plain values, checked to exist.

Meshes and images are one file each (globs and ``{bundled}`` / ``{data_root}`` templates expanded,
:mod:`topomatch.pipeline.paths`); an image pair is two files and its known transform (``truth``), listed in
the config or in a CSV table. The pair's words (fixed, moving, truth) are registration's: they stay here, the
one engine module that names them, because the config format has them (``inputs: {pairs: ...}``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from topomatch.pipeline.errors import InputError
from topomatch.pipeline.paths import display_path, resolve_input
from topomatch.pipeline.schema import InputsConfig, PairsCsvConfig

#: State entries that each kind of input provides before the first stage.
INPUT_STATE = {
    "meshes": ("path",),
    "images": ("path",),
    "pairs": ("fixed_path", "moving_path", "truth"),
    "pairs_csv": ("fixed_path", "moving_path", "truth"),
}


@dataclass(frozen=True)
class InputUnit:
    """One input of a run: files for state entries (``paths``) and plain values (``values``)."""

    label: str
    paths: dict[str, Path]
    values: dict[str, Any] = field(default_factory=dict)

    @property
    def primary(self) -> Path:
        return next(iter(self.paths.values()))


def resolve_inputs_config(inputs: InputsConfig, *, base_dir: Path, data_root: Path | None) -> list[InputUnit]:
    """Expand every kind of input into :class:`InputUnit` objects (files checked to exist)."""
    units: list[InputUnit] = []

    def one(template: str, where: str, base: Path = base_dir) -> list[Path]:
        return resolve_input(template, base_dir=base, root=data_root, where=where)

    for kind in ("meshes", "images"):
        seen: set[Path] = set()
        for i, template in enumerate(getattr(inputs, kind)):
            for p in one(template, f"inputs.{kind}[{i}]"):
                if p.resolve() not in seen:  # a file two entries (or overlapping globs) name is one input, not two
                    seen.add(p.resolve())
                    units.append(InputUnit(display_path(p, data_root), {"path": p}))
    for i, pair in enumerate(inputs.pairs):
        (fixed,) = one(pair.fixed, f"inputs.pairs[{i}].fixed")[:1]
        (moving,) = one(pair.moving, f"inputs.pairs[{i}].moving")[:1]
        units.append(InputUnit(pair.label or f"{fixed.name}|{moving.name}", {"fixed_path": fixed, "moving_path": moving},
                               {"truth": pair.truth}))
    if inputs.pairs_csv is not None:
        units += _pairs_from_csv(inputs.pairs_csv, one)
    return units


def _pairs_from_csv(spec: PairsCsvConfig, one) -> list[InputUnit]:
    """One pair per row of the pairs table; every problem of the table is an InputError naming it."""
    import csv

    (path,) = one(spec.path, "inputs.pairs_csv.path")[:1]
    if not path.is_file():
        raise InputError(path, "not a regular file: the pairs table is a CSV file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = list(csv.DictReader(fh, strict=True))
    except UnicodeDecodeError as exc:
        raise InputError(path, f"not a UTF-8 text file (byte {exc.start})") from None
    except csv.Error as exc:
        raise InputError(path, f"malformed CSV ({exc})") from None
    if not rows:
        raise InputError(path, "the pairs table has no rows")
    units = []
    for r, row in enumerate(rows):
        where = f"row {r + 2}"
        wanted = [spec.fixed_column, spec.moving_column, *spec.truth_columns.values()]
        missing = [c for c in wanted if c not in row]
        if missing:
            raise InputError(path, f"{where}: no column {missing[0]!r} (columns: {', '.join(map(str, row))})")
        short = any(row[c] is None for c in wanted)  # DictReader's marks: None values (short), a None key (long)
        if short or None in row:
            raise InputError(path, f"{where}: {'too few' if short else 'too many'} cells for the "
                                   f"{len(row) - (None in row)} columns of the header")
        cells = {name: row[col].strip() for name, col in spec.truth_columns.items()}
        if any(v == "" for v in cells.values()):
            if spec.skip_missing_truth:
                continue
            raise InputError(path, f"{where}: empty truth cell")
        try:
            truth = {name: float(v) for name, v in cells.items()} or None
        except ValueError as exc:
            raise InputError(path, f"{where}: truth is not a number ({exc})") from None
        if truth and not all(math.isfinite(v) for v in truth.values()):
            raise InputError(path, f"{where}: truth is not a finite number ({cells})")
        fixed = one(row[spec.fixed_column], f"{path}: {where} fixed", path.parent)[0]
        moving = one(row[spec.moving_column], f"{path}: {where} moving", path.parent)[0]
        units.append(InputUnit(f"{fixed.name}|{moving.name}", {"fixed_path": fixed, "moving_path": moving},
                               {"truth": truth}))
    if not units:
        raise InputError(path, "every row lacks its truth (skip_missing_truth): no pairs to register")
    return units
