"""A turning record CSV that cannot be read is refused by ``IdentificationError`` naming
the file, and the row and column of a cell that is not a number."""

from __future__ import annotations

import pytest

from machining_envs.identification import IdentificationError, read_turning_record

HEADER = "time_s,command,force_N,spindle_rpm,depth_mm\n"


@pytest.mark.parametrize(
    "content,message",
    [
        (bytes(range(128, 256)), "rec.csv: not a CSV record \\(not UTF-8 text\\)"),
        ((HEADER + "0,1,2,300,1\n0.1,1,2\n").encode(), "rec.csv: row 3, column spindle_rpm"),
        ((HEADER + "0,1,2,300,1\n0.1,1,abc,300,1\n").encode(), "rec.csv: row 3, column force_N"),
        ((HEADER + "0,1,,300,1\n").encode(), "rec.csv: row 2, column force_N"),
    ],
)
def test_an_unreadable_record_is_refused_naming_the_file_row_and_column(tmp_path, content, message):
    path = tmp_path / "rec.csv"
    path.write_bytes(content)
    with pytest.raises(IdentificationError, match=message):
        read_turning_record(path)


def test_a_readable_record_gives_its_columns(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text(HEADER + "0,1,2,300,1\n0.1,1.5,2.5,300,1\n")
    cols = read_turning_record(path)
    assert cols["force_N"].tolist() == [2.0, 2.5] and set(cols) == set(HEADER.strip().split(","))
