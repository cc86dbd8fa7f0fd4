"""Fuzzing the field-log reader: random byte and CSV mutations of a valid log.

Every mutated folder must either parse into a valid :class:`FieldLog` (strictly increasing finite
times, finite voltages within the bus limit: no silent NaN reaches the replay input) or raise a
:class:`FieldLogError` (a ``ValueError``) whose message names the file. Anything else (a ``KeyError``,
``IndexError``, ``UnicodeError``, a pandas error ...) is a traceback and fails. The input files are
never modified by reading.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from trackenv.fieldlog import FieldLogError, read_field_log  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SRC = ROOT / "data" / "field" / "thesis" / "go_stop_dry_sand"
CSV_LINES = (SRC / "log.csv").read_text().splitlines()[:25]  # header + 24 samples
CSV = "\n".join(CSV_LINES) + "\n"
META = (SRC / "meta.json").read_text()
BUDGET = settings().max_examples * 6

SPECIAL = ["", "nan", "NaN", "inf", "-inf", "1e400", "-0", "0x10", "1,5", ";", '"', '"unterminated', "\x00", "NA",
           " 1 ", "1e-400", "24.0000001", "-24", "true", "\ufeff", "é", "\r"]


def check(folder: Path, files: dict[str, bytes]) -> None:
    for name, data in files.items():
        (folder / name).write_bytes(data)
    before = {n: hashlib.sha256((folder / n).read_bytes()).hexdigest() for n in files}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            log = read_field_log(folder)
        except FieldLogError as exc:
            msg = str(exc)
            assert str(folder) in msg and ("log.csv" in msg or "meta.json" in msg), msg
            assert "np.float" not in msg, msg
        else:
            t, v = log.t, log.volts
            assert len(log) >= 2 and np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)
            assert np.all(np.isfinite(v)) and np.all(np.abs(v) <= 24.0 + 1e-9)
            for ch in log.measured().values():
                assert ch.dtype == np.float64 and not np.any(np.isinf(ch))
    after = {n: hashlib.sha256((folder / n).read_bytes()).hexdigest() for n in files}
    assert before == after


@st.composite
def byte_mutations(draw, data: bytes):
    b = bytearray(data)
    for _ in range(draw(st.integers(1, 8))):
        kind = draw(st.sampled_from(["replace", "insert", "delete", "truncate"]))
        pos = draw(st.integers(0, max(0, len(b) - 1)))
        if kind == "replace" and b:
            b[pos] = draw(st.integers(0, 255))
        elif kind == "insert":
            b[pos:pos] = draw(st.binary(min_size=1, max_size=4))
        elif kind == "delete" and b:
            del b[pos:pos + draw(st.integers(1, 16))]
        elif kind == "truncate":
            b = b[:pos]
    return bytes(b)


@st.composite
def csv_mutations(draw):
    rows = [line.split(",") for line in CSV_LINES]
    for _ in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["cell", "cell_text", "drop_row", "dup_row", "swap_rows", "drop_col",
                                     "rename_col", "extra_col", "blank_line", "short_row"]))
        r = draw(st.integers(0, len(rows) - 1))
        c = draw(st.integers(0, len(rows[0]) - 1))
        if kind == "cell" and c < len(rows[r]):
            rows[r][c] = draw(st.sampled_from(SPECIAL))
        elif kind == "cell_text" and c < len(rows[r]):
            rows[r][c] = draw(st.text(max_size=6))
        elif kind == "drop_row" and len(rows) > 1:
            rows.pop(r)
        elif kind == "dup_row":
            rows.insert(r, list(rows[r]))
        elif kind == "swap_rows" and r + 1 < len(rows):
            rows[r], rows[r + 1] = rows[r + 1], rows[r]
        elif kind == "drop_col":
            rows = [row[:c] + row[c + 1:] for row in rows]
        elif kind == "rename_col" and c < len(rows[0]):
            rows[0][c] = draw(st.sampled_from(["T", "V_LEFT", "time", "", "t", "i_left", rows[0][c] + " "]))
        elif kind == "extra_col":
            rows = [row + [draw(st.sampled_from(["x", "1", "", "note"]))] for row in rows]
        elif kind == "blank_line":
            rows.insert(r, [])
        elif kind == "short_row" and rows[r]:
            rows[r] = rows[r][:-1]
        if not rows or not rows[0]:
            rows = [["t"]]
    return ("\n".join(",".join(row) for row in rows) + "\n").encode("utf-8", "surrogatepass")


@st.composite
def meta_mutations(draw):
    meta = json.loads(META)
    for _ in range(draw(st.integers(1, 3))):
        key = draw(st.sampled_from(["terrain", "maneuver", "current_sensor", "vehicle", "notes", "synthetic"]))
        kind = draw(st.sampled_from(["drop", "value"]))
        if kind == "drop":
            meta.pop(key, None)
        else:
            meta[key] = draw(st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=True),
                                       st.text(max_size=8), st.sampled_from(["asphalt", "signed", "absolute",
                                                                              "talon", ""]),
                                       st.lists(st.integers(), max_size=2)))
    top = draw(st.sampled_from(["object", "object", "object", "list", "string"]))
    doc = meta if top == "object" else ([meta] if top == "list" else "meta")
    return json.dumps(doc).encode()


@settings(max_examples=BUDGET)
@given(data=st.data())
def test_byte_mutations_of_log_csv(data, tmp_path):
    check(tmp_path, {"log.csv": data.draw(byte_mutations(CSV.encode())), "meta.json": META.encode()})


@settings(max_examples=BUDGET)
@given(data=st.data())
def test_byte_mutations_of_meta_json(data, tmp_path):
    check(tmp_path, {"log.csv": CSV.encode(), "meta.json": data.draw(byte_mutations(META.encode()))})


@settings(max_examples=BUDGET)
@given(csv=csv_mutations())
def test_csv_mutations(csv, tmp_path):
    check(tmp_path, {"log.csv": csv, "meta.json": META.encode()})


@settings(max_examples=BUDGET)
@given(meta=meta_mutations())
def test_meta_mutations(meta, tmp_path):
    check(tmp_path, {"log.csv": CSV.encode(), "meta.json": meta})


def test_unmutated_log_parses(tmp_path):
    """The fuzzers start from a valid log (otherwise they test only the error path)."""
    (tmp_path / "log.csv").write_text(CSV)
    (tmp_path / "meta.json").write_text(META)
    assert len(read_field_log(tmp_path)) == 24
