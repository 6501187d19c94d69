"""The CSV and NPZ readers refuse what would hang or mislead them, naming the file and field: a
CSV field beyond csv's size limit, a header thousands of columns wide, digits grouped by '_', an
NPZ that is no zip archive, holds Python objects or declares a gigantic field; only the fields a
data set uses are read from an NPZ."""

from __future__ import annotations

import pathlib
import time
import zipfile

import numpy as np
import pytest

import jflex
from jflex.data._csv import MAX_COLUMNS, Table
from jflex.data._npz import MAX_FIELD_BYTES, load_npz_fields
from jflex.gap import load_case
from test_case_checks import _load_quiet, _long_case


def _csv(path: pathlib.Path, head, rows):
    path.write_text(",".join(head) + "\n" + "\n".join(",".join(r) for r in rows) + "\n")
    return path


def test_oversized_csv_field_is_a_named_error(tmp_path):
    p = _csv(tmp_path / "big.csv", ["t", "q"], [["0", "1"], ["0.1", '"' + "9" * 200_000 + '"'], ["0.2", "1"]])
    with pytest.raises(jflex.DataError, match=r"big.csv: line 3: not a CSV row of numbers"):
        Table(p)


def test_wide_header_refused_before_the_rows_are_parsed(tmp_path):
    head = ["t", "q"] + [f"x{k}" for k in range(MAX_COLUMNS)]
    p = tmp_path / "wide.csv"
    p.write_text(",".join(head) + "\n" + ("0," * (len(head) - 1) + "0\n") * 400)
    t0 = time.perf_counter()
    with pytest.raises(jflex.DataError, match=rf"wide.csv: line 1: the header declares {MAX_COLUMNS + 2} columns"):
        Table(p)
    assert time.perf_counter() - t0 < 5.0


def test_header_at_the_limit_reads_fast(tmp_path):
    # duplicate names are found by counting, not by a scan per name (quadratic in the width)
    head = ["t", "q"] + [f"x{k}" for k in range(MAX_COLUMNS - 2)]
    p = tmp_path / "ok.csv"
    p.write_text(",".join(head) + "\n" + "\n".join(f"{k},{k * k}," + ",".join(["1"] * (MAX_COLUMNS - 2))
                                                    for k in range(50)) + "\n")
    t0 = time.perf_counter()
    tb = Table(p)
    assert time.perf_counter() - t0 < 10.0
    np.testing.assert_array_equal(tb.column("q"), np.arange(50.0) ** 2)


@pytest.mark.parametrize("cell", ["1_000", "1_0.5", "_1"])
def test_underscore_digits_are_not_numbers(tmp_path, cell):
    p = _csv(tmp_path / "u.csv", ["t", "q"], [["0", "1"], ["0.1", cell], ["0.2", "3"]])
    with pytest.raises(jflex.DataError, match=rf"u.csv: column 'q', line 3: expected a number, got '{cell}'"):
        Table(p).column("q")
    assert float("1_000") == 1000.0  # what Python would have read


def test_garbage_npz_in_jflex_words(tmp_path):
    p = tmp_path / "g.npz"
    p.write_bytes(b"PK\x03\x04 not really a zip" + bytes(range(200)))
    with pytest.raises(jflex.DataError, match=r"g.npz is not a valid NPZ file") as e:
        load_npz_fields(p, "datasets[0].file", "case.yaml")
    assert "allow_pickle" not in str(e.value)


def test_object_array_npz_refused_in_jflex_words(tmp_path):
    p = tmp_path / "o.npz"
    np.savez(p, t=np.arange(3.0), tau=np.array([{"a": 1}, None], dtype=object))
    with pytest.raises(jflex.DataError, match=r"o.npz: field 'tau': holds Python objects") as e:
        load_npz_fields(p, "datasets[0].file", "case.yaml")
    assert "allow_pickle" not in str(e.value)


def _declare_huge(path, key, shape):
    """Add member ``key`` whose .npy header declares ``shape`` float64 but holds a few bytes: what
    a crafted archive does to make a reader allocate or inflate gigabytes."""
    from numpy.lib import format as F
    import io

    buf = io.BytesIO()
    F.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": shape})
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr(f"{key}.npy", buf.getvalue() + b"\0" * 64)


def test_unused_huge_npz_key_is_not_read(tmp_path):
    folder = _long_case(tmp_path)
    _declare_huge(folder / "traj0.npz", "junk", (1 << 28,))  # 2 GiB declared, unused by a torque set
    t0 = time.perf_counter()
    case, _ = _load_quiet(folder)
    assert time.perf_counter() - t0 < 30
    assert "junk" not in case.datasets[0].arrays


def test_used_npz_key_refused_by_its_declared_size(tmp_path):
    folder = _long_case(tmp_path)
    z = dict(np.load(folder / "traj0.npz"))
    del z["tau"]
    np.savez(folder / "traj0.npz", **z)
    _declare_huge(folder / "traj0.npz", "tau", (1 << 27, 2))
    assert (1 << 27) * 2 * 8 > MAX_FIELD_BYTES
    with pytest.raises(jflex.DataError, match=r"traj0.npz: field 'tau': declares shape \(134217728, 2\) of float64 "
                       r"\(2 GiB\); expected at most 1 GiB per field"):
        load_case(folder)
