"""Reading class labels: paths relative to the CSV, a byte-order mark tolerated, conflicts refused."""

from __future__ import annotations

import pytest

from topomatch.pipeline.errors import InputError
from topomatch.stages.retrieval.labels import read_labels


def test_paths_resolve_against_the_csv_folder_and_a_bom_is_not_part_of_the_header(tmp_path):
    csv = tmp_path / "labels.csv"
    csv.write_text("\ufeffrelative_path,class\nsub/a.off,cup\nb.off,chair\nb.off,chair\n", encoding="utf-8")
    assert read_labels(csv) == {str((tmp_path / "sub/a.off").resolve()): "cup",
                                str((tmp_path / "b.off").resolve()): "chair"}


def test_one_mesh_with_two_classes_is_refused(tmp_path):
    csv = tmp_path / "labels.csv"
    csv.write_text("path,label\na.off,cup\nb.off,chair\na.off,mug\n")
    with pytest.raises(InputError, match=r"labels\.csv: 'a\.off' has class 'cup' on row 2 and 'mug' on row 4"):
        read_labels(csv)
