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
        The file is missing, unreadable or lacks the columns (names the file).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "labels file not found")
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            cols = reader.fieldnames or []
            pcol = next((c for c in ("relative_path", "path") if c in cols), None)
            lcol = next((c for c in ("class", "label") if c in cols), None)
            if pcol is None or lcol is None:
                raise InputError(path, f"labels CSV needs a relative_path (or path) and a class (or label) column; "
                                       f"found {', '.join(cols) or 'no header'}")
            return {str((path.parent / row[pcol]).resolve()): row[lcol] for row in reader
                    if row.get(pcol) and row.get(lcol)}
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(path, f"cannot read the labels CSV ({exc})") from None
