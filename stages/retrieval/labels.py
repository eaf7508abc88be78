"""Class labels of a mesh collection, from a CSV file."""

from __future__ import annotations

import csv
from pathlib import Path

from topomatch.pipeline.contract import InputError


def read_labels(path: str | Path) -> dict[str, str]:
    """{resolved mesh path: label} from a CSV with relative_path|path and class|label columns.

    Paths are relative to the CSV's folder.

    Raises
    ------
    InputError
        The file is missing, unreadable or lacks the columns, or names one mesh twice with two
        different classes (names the file and the rows).
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "labels file not found")
    if not path.is_file():  # a folder, or a FIFO that would block the read
        raise InputError(path, "not a regular file: the labels are a CSV file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            reader = csv.DictReader(fh)
            cols = reader.fieldnames or []
            pcol = next((c for c in ("relative_path", "path") if c in cols), None)
            lcol = next((c for c in ("class", "label") if c in cols), None)
            if pcol is None or lcol is None:
                raise InputError(path, f"labels CSV needs a relative_path (or path) and a class (or label) column; "
                                       f"found {', '.join(cols) or 'no header'}")
            labels: dict[str, str] = {}
            first_row: dict[str, int] = {}
            for r, row in enumerate(reader, start=2):
                if not (row.get(pcol) and row.get(lcol)):
                    continue
                key = str((path.parent / row[pcol]).resolve())
                if key in labels and labels[key] != row[lcol]:
                    raise InputError(path, f"{row[pcol]!r} has class {labels[key]!r} on row {first_row[key]} and "
                                           f"{row[lcol]!r} on row {r}")
                labels[key] = row[lcol]
                first_row.setdefault(key, r)
            return labels
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(path, f"cannot read the labels CSV ({exc})") from None
