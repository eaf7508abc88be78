"""Registration's input kinds: single ``images`` (state ``path``) and image ``pairs`` (state ``fixed_path``,
``moving_path`` and the known transform ``truth``), listed in the config or in a CSV table (``pairs_csv``).

``truth`` is a mapping of parameter names to values ({tx, ty, angle} in 2D, {tx, ty, tz, ax, ay, az} in 3D), or None
when the pair has no known transform (the ``evaluate`` stages then refuse it)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from pydantic import Field

from topomatch.pipeline.contract import InputError, InputFiles, InputUnit, Params, input_kind

#: The state entries of one pair.
PAIR_STATE = ("fixed_path", "moving_path", "truth")


class PairConfig(Params):
    """A fixed/moving image pair with an optional known transform."""

    fixed: str
    moving: str
    truth: dict[str, float] | None = Field(None, description="known parameters, e.g. {tx: 13, ty: 17, angle: 0}")
    label: str | None = Field(None, min_length=1, description="the pair's name in tables and figures, e.g. 'slice "
                                                             "30|slice 31' (default: the two file names)")


class PairsCsvConfig(Params):
    """Image pairs listed in a CSV file (paths relative to the CSV's folder)."""

    path: str
    fixed_column: str = "fixed"
    moving_column: str = "moving"
    truth_columns: dict[str, str] = Field(default_factory=dict, description="truth name -> CSV column")
    skip_missing_truth: bool = Field(True, description="leave out rows whose truth cells are empty")


def _pair(fixed: Path, moving: Path, truth: dict[str, float] | None, label: str | None = None) -> InputUnit:
    return InputUnit(label or f"{fixed.name}|{moving.name}", {"fixed_path": fixed, "moving_path": moving},
                     {"truth": truth})


@input_kind("images", schema=list[str], provides=("path",))
def images(templates: list[str], files: InputFiles) -> list[InputUnit]:
    """Image files, as path templates ({bundled}, {data_root}, globs): one input per file."""
    return files.each(templates, "inputs.images")


@input_kind("pairs", schema=list[PairConfig], provides=PAIR_STATE)
def pairs(entries: list[PairConfig], files: InputFiles) -> list[InputUnit]:
    """Image pairs listed in the config, each with its optional known transform and label."""
    return [_pair(files.one(p.fixed, f"inputs.pairs[{i}].fixed"), files.one(p.moving, f"inputs.pairs[{i}].moving"),
                  p.truth, p.label) for i, p in enumerate(entries)]


@input_kind("pairs_csv", schema=PairsCsvConfig | None, provides=PAIR_STATE)
def pairs_csv(spec: PairsCsvConfig, files: InputFiles) -> list[InputUnit]:
    """Image pairs, one per row of a CSV table; every problem of the table is an InputError naming it."""
    path = files.one(spec.path, "inputs.pairs_csv.path")
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
        if missing := [c for c in wanted if c not in row]:
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
        units.append(_pair(files.one(row[spec.fixed_column], f"{path}: {where} fixed", path.parent),
                           files.one(row[spec.moving_column], f"{path}: {where} moving", path.parent), truth))
    if not units:
        raise InputError(path, "every row lacks its truth (skip_missing_truth): no pairs to register")
    return units
