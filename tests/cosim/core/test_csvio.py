"""The shared CSV reader (its wordings, blank rows, whole-file mode) and the writers."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from cosim.core import csvio
from cosim.core.errors import CosimError

PLAIN = csvio.Wording(not_found="{path}: gone",
                      cell_count="{path}:{line}:{col}: {cells}/{expected}",
                      not_a_number="{path}:{line}:{col}: {name}={cell}?",
                      not_finite="{path}:{line}:{col}: {name} not finite")


def write(tmp_path: Path, data: str | bytes) -> Path:
    path = tmp_path / "f.csv"
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def test_rows_carry_their_line_and_skip_blank_rows(tmp_path: Path) -> None:
    path = write(tmp_path, 'time,"a"\n0,1\n\n , \n2,3\n')
    with csvio.CsvReader(path) as f:
        assert f.header() == ["time", "a"]
        assert list(f.rows(2)) == [(2, ["0", "1"]), (5, ["2", "3"])]


def test_blank_rows_are_rows_when_asked(tmp_path: Path) -> None:
    path = write(tmp_path, "time,a\n0,1\n\n")
    with csvio.CsvReader(path, PLAIN) as f, pytest.raises(CosimError) as info:
        list(f.rows(len(f.header()), skip_blank=False))
    assert str(info.value) == f"{path}:3:1: 0/2"


def test_each_kind_of_file_keeps_its_wording(tmp_path: Path) -> None:
    with pytest.raises(CosimError, match=r"f\.csv: gone$"):
        csvio.CsvReader(tmp_path / "f.csv", PLAIN)
    with pytest.raises(CosimError, match=r"f\.csv: no such file$"):
        csvio.CsvReader(tmp_path / "f.csv")
    with pytest.raises(CosimError, match="is a directory, expected a CSV file"):
        csvio.CsvReader(tmp_path)
    path = write(tmp_path, "time,a\n0,1,2\n")
    with csvio.CsvReader(path, PLAIN) as f, pytest.raises(CosimError) as info:
        list(f.rows(len(f.header())))
    assert str(info.value) == f"{path}:2:3: 3/2"


def test_numbers_name_line_column_and_column_name(tmp_path: Path) -> None:
    path = tmp_path / "f.csv"
    assert csvio.parse_number(path, PLAIN, " 2.5 ", 3, 2, "a") == 2.5
    with pytest.raises(CosimError, match=r"f\.csv:3:2: a=x\?$"):
        csvio.parse_number(path, PLAIN, "x", 3, 2, "a")
    with pytest.raises(CosimError, match=r"f\.csv:3:2: a not finite$"):
        csvio.parse_number(path, PLAIN, "inf", 3, 2, "a")
    assert np.isnan(csvio.parse_number(path, PLAIN, "nan", 3, 2, "a", finite=False))
    with pytest.raises(CosimError, match=r"f\.csv:3:2: empty value in column 'a'$"):
        csvio.parse_number(path, csvio.RESULT_WORDING, " ", 3, 2, "a")


def test_not_text_and_malformed_files(tmp_path: Path) -> None:
    path = write(tmp_path, b"time,a\n0,\xff\n")
    with csvio.CsvReader(path) as f, pytest.raises(CosimError, match="not a text CSV file"):
        list(f.rows(len(f.header())))
    with pytest.raises(CosimError, match="not a text CSV file"):  # whole file: at once
        csvio.CsvReader(path, whole_file=True)
    path = write(tmp_path, 'time,a\n0,"' + "x" * 200_000 + '"\n')
    with csvio.CsvReader(path) as f, pytest.raises(CosimError, match="malformed CSV: field"):
        list(f.rows(len(f.header())))
    with csvio.CsvReader(write(tmp_path, ""), PLAIN) as f, \
            pytest.raises(CosimError, match="empty file, expected a header row"):
        f.header()


def test_whole_file_mode_drops_a_byte_order_mark(tmp_path: Path) -> None:
    path = write(tmp_path, b"\xef\xbb\xbftime,a\r\n0,1\r\n")
    with csvio.CsvReader(path, encoding="utf-8-sig", whole_file=True) as f:
        assert f.header() == ["time", "a"] and list(f.rows(2)) == [(2, ["0", "1"])]


def test_cross_check_writer_round_trips_through_read_table(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    rows = [[0.0, 0.1, float("nan")], [25.0, 1 / 3, -2e-300]]
    csvio.write_csv(path, ["time", 'a"b', "c"], rows)
    assert path.read_bytes().startswith(b'"time","a""b","c"\n0.0,0.1,nan\n')
    table = csvio.read_table(path)
    assert table.names == ['a"b', "c"] and table.time.tolist() == [0.0, 25.0]
    assert table.column('a"b').tolist() == [0.1, 1 / 3]
    assert csvio.row_lines([[1.0], [2.0, 3.0, 4.0]], width=2) == "1.0,nan\n2.0,3.0\n"


def test_table_writer_uses_the_csv_dialect_and_full_precision() -> None:
    fh = io.StringIO(newline="")
    csvio.write_table(fh, ["time", "q", "split"], [[0.0, np.float64(0.1), "train"],
                                                   [25.0, 1 / 3, "a,b"]])
    assert fh.getvalue() == ("time,q,split\r\n0.0,0.1,train\r\n"
                             '25.0,0.3333333333333333,"a,b"\r\n')
