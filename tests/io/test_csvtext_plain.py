"""The whole-file CSV reader's fast path (Arrow's reader after the header line) against the
line-by-line reader (the csv module), on plain files and on every kind of line that must fall back."""

import numpy as np
import pytest

from trackproc.errors import InputError
from trackproc.io import csvtext

HEADER = b"time,station,doppler_hz,elevation_deg\n"
ROWS = b"".join(b"2026-03-20T09:30:%02d.000000Z,CPH,%r,%r\n" % (i, -3846.3 - i * 0.5, 66.1 - i * 0.01)
                for i in range(40))


def _line_by_line(data: bytes):
    text = csvtext.decode_text(data, "f.csv")
    records, starts, comments, _ = csvtext._records(text, "f.csv", 0)
    header, header_row = records.pop(0), starts.pop(0)
    return csvtext._text_table(header, records, starts, header_row, comments, "f.csv")


CASES = {
    "plain": HEADER + ROWS,
    "bom": b"\xef\xbb\xbf" + HEADER + ROWS,
    "spaces": HEADER + ROWS.replace(b",CPH,", b", CPH ,"),
    "tab and nbsp": HEADER + ROWS.replace(b",CPH,", b",\tCPH\xc2\xa0,"),
    "comment": HEADER + b"# a comment\n" + ROWS,
    "blank line": HEADER + ROWS + b"\n" + ROWS,
    "comma-only line": HEADER + b",,,\n" + ROWS,
    "quoted": HEADER + ROWS.replace(b",CPH,", b',"CPH",', 1),
    "crlf": HEADER + ROWS.replace(b"\n", b"\r\n"),
    "no final newline": HEADER + ROWS[:-1],
    "header only": HEADER,
    "empty cells": HEADER + ROWS.replace(b",CPH,", b",CPH,,", 1).replace(b",66.1\n", b"\n", 1),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_whole_file_reader_matches_the_line_by_line_reader(name):
    data = CASES[name]
    assert csvtext._is_plain(data) == (not csvtext._NOT_PLAIN.search(data))
    fast_path = csvtext._plain_table(data, csvtext.decode_text(data, "f.csv"), "f.csv") is not None
    assert fast_path == (name in ("plain", "bom", "spaces", "tab and nbsp", "empty cells"))
    fast = csvtext.parse_text_table(data, "f.csv")
    slow = _line_by_line(data)
    assert fast.columns == slow.columns and fast.header_row == slow.header_row and fast.comments == slow.comments
    assert np.array_equal(fast.rows, slow.rows)
    for column in slow.columns:
        assert fast.cells[column].dtype == object
        assert list(fast.cells[column]) == list(slow.cells[column]) and \
            all(type(c) is str for c in fast.cells[column])


def test_wrong_number_of_fields_is_the_same_error():
    data = HEADER + ROWS + b"2026-03-20T09:31:00Z,CPH,1.0\n" + ROWS
    with pytest.raises(InputError) as fast:
        csvtext.parse_text_table(data, "f.csv")
    with pytest.raises(InputError) as slow:
        _line_by_line(data)
    assert str(fast.value) == str(slow.value) and "wrong number of fields" in str(fast.value)


@pytest.mark.parametrize("seed", range(4))
def test_plainness_is_the_regular_expressions_answer_on_drawn_text(seed):
    """_is_plain (substring and newline tests) against _NOT_PLAIN itself: pass-file text, short and
    long (the two ways of finding a line that starts with a newline or comma), with one or two of
    the bytes and sequences the regular expression looks for at drawn places, the first and the last
    included."""
    rng = np.random.default_rng(seed)
    pieces = [b"\n", b",", b" ", b"\t", b'"', b"#", b"\r", b"\x00", b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e",
              b"\xc2\x85", b"\xe2\x80\xa8", b"\xe2\x80\xa9", b"\xc2\xa0", b"\xe2\x80\xa7", b"\xc2", b"\n\n", b"\n,",
              b"\n \n", b"\n\t,", b",\n", b"\xe2\x80"]
    seen = {True: 0, False: 0}
    for _ in range(400):
        body = ROWS[:int(rng.integers(1, 3)) * int(rng.choice([20, 200, len(ROWS) // 2]))]
        data = bytearray(HEADER + body)
        for _ in range(int(rng.integers(0, 3))):
            at = int(rng.choice([0, len(data), int(rng.integers(0, len(data) + 1))]))
            data[at:at] = pieces[int(rng.integers(len(pieces)))]
        data = bytes(data)
        expected = not csvtext._NOT_PLAIN.search(data)
        assert csvtext._is_plain(data) == expected, data
        seen[expected] += 1
    assert min(seen.values()) > 50
