"""CSV data sets: a log plus its column map (:class:`jflex.data.LogMap`, the case loader's
translation of a case.yaml data set), read into the arrays an NPZ data set holds (``t``, ``q``,
``tau``, ...); the case loader then checks them like any NPZ.

Only the mapped columns are parsed (a log may carry text columns besides). Each value is the raw
cell minus its ``offset``, times its ``scale`` factor (e.g. motor current [A] x torque constant x
gear ratio), in the units ``units`` names (time s, ms, us or ns; angles rad or deg), converted to
SI here; torques then pass the optional ``coupling`` of the transmission and get their
``torque_offset``: ``tau = K^T (k (i - i0)) + offset`` (:func:`jflex.data.currents_to_torque`).
A data set may name several CSV files of one run (positions, velocities, efforts): each holds the
time column, and they are merged on time (:func:`jflex.data.merge_on_time`).
"""

from __future__ import annotations

import collections
import csv
import pathlib

import numpy as np

from .._errors import ConfigError, DataError
from ._condition import merge_on_time
from ._log_map import LogMap
from ._posture import yaml_posture
from ._record import Channel, Record

DELIMITERS = {",": ",", ";": ";", "tab": "\t", "space": None}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
MAX_COLUMNS = 10_000  # a log's header at most this wide (see Table)


class Table:
    """The header and the rows (strings) of a CSV file, with each row's line number."""

    def __init__(self, path: pathlib.Path, delimiter: str | None = None, sniff: bool = True):
        self.path = path
        try:
            text = path.read_text(encoding="utf-8-sig")
        except UnicodeDecodeError as exc:
            raise DataError(f"{path}: not UTF-8 text (undecodable byte at offset {exc.start})") from None
        except OSError as exc:
            raise DataError(f"{path}: cannot be read ({exc.strerror})") from None
        lines = [(k + 1, s) for k, s in enumerate(text.splitlines()) if s.strip() and not s.lstrip().startswith("#")]
        if not lines:
            raise DataError(f"{path}: no header line (the file is empty or holds only '#' comments)")
        first = lines[0][1]
        declared = max(first.count(d) for d in (",", ";", "\t")) + 1 if delimiter is not None or sniff else 0
        declared = max(declared, len(first.split()) if delimiter is None and not sniff else 0)
        if declared > MAX_COLUMNS:
            # refused by its header before any row is split: every row is parsed whole, and a file
            # this wide (a dump of every signal) takes minutes for the few columns a case maps
            raise DataError(f"{path}: line {lines[0][0]}: the header declares {declared} columns; expected at most "
                            f"{MAX_COLUMNS} (keep the columns the case maps, e.g. with a spreadsheet or 'cut')")
        if sniff and delimiter is None:
            counts = {d: lines[0][1].count(d) for d in (",", ";", "\t")}
            best = max(counts, key=counts.get)
            delimiter = best if counts[best] else None
        if delimiter is None:
            cells = [s.split() for _, s in lines]
        else:
            reader = csv.reader((s for _, s in lines), delimiter=delimiter)
            try:
                cells = list(reader)
            except csv.Error as exc:  # a field over csv's size limit (131072 characters), a stray NUL
                k = lines[min(reader.line_num, len(lines)) - 1][0]
                raise DataError(f"{path}: line {k}: not a CSV row of numbers ({exc}); expected a log of numeric "
                                "fields") from None
        self.header = [h.strip() for h in cells[0]]
        if any(not h for h in self.header):
            raise DataError(f"{path}: line {lines[0][0]}: the header has an empty column name ({self.header})")
        dup = sorted(h for h, c in collections.Counter(self.header).items() if c > 1)
        if dup:
            raise DataError(f"{path}: line {lines[0][0]}: column names {dup} appear more than once in the header")
        self.lines = [k for k, _ in lines[1:]]
        self.rows = cells[1:]
        for k, row in zip(self.lines, self.rows):
            if len(row) != len(self.header):
                raise DataError(f"{path}: line {k}: {len(row)} fields, the header has {len(self.header)}")
        if not self.rows:
            raise DataError(f"{path}: a header but no data lines")

    def column(self, name: str) -> np.ndarray:
        """The column ``name`` as floats (an empty cell is NaN); a non-number names its line."""
        i = self.header.index(name)
        cells = [r[i].strip() or "nan" for r in self.rows]
        try:
            values = np.asarray(cells, dtype=float)
            # Python's float() reads '1_000' as 1000 (a literal's digit grouping); in a log it is a
            # typing slip or another field's separator, not a number
            k = next((k for k, c in zip(self.lines, cells) if "_" in c), None)
            if k is not None:
                raise DataError(f"{self.path}: column {name!r}, line {k}: expected a number, got "
                                f"{cells[self.lines.index(k)]!r} (digits grouped by '_' are not read)")
            return values
        except ValueError:
            for k, c in zip(self.lines, cells):
                try:
                    float(c)
                except ValueError:
                    raise DataError(f"{self.path}: column {name!r}, line {k}: expected a number, got {c!r}") from None
            raise


def _tables(paths, m):
    case_file, fld = m.where
    tables = []
    for p in paths:
        if not p.is_file():
            raise ConfigError(f"{case_file}: field '{fld}.file': data file {p} not found")
        tables.append(Table(p, DELIMITERS[m.delimiter] if m.delimiter else None, sniff=m.delimiter is None))
    return tables


def transmission(motor, order, m: LogMap):
    """Joint torques (N, n) from the scaled motor torques ``motor`` (columns in joint ``order``):
    the ``coupling`` matrix of the log map ``m`` applied to the joints it names, then its
    ``torque_offset``."""
    case_file, fld = m.where
    tau = np.array(motor, float)
    cp = m.coupling
    if cp is not None:
        missing = [j for j in cp["joints"] if j not in order]
        if missing:
            raise ConfigError(f"{case_file}: field '{fld}.coupling.joints': {missing} have no torque column "
                              f"(torque joints {list(order)})")
        sel = [list(order).index(j) for j in cp["joints"]]
        tau[:, sel] = motor[:, sel] @ np.asarray(cp["matrix"], float)
    off = m.torque_offset or {}
    for j, v in off.items():
        if j not in order:
            raise ConfigError(f"{case_file}: field '{fld}.torque_offset.{j}': {j!r} has no torque column "
                              f"(torque joints {list(order)})")
        tau[:, list(order).index(j)] += v
    return tau


def motor_angles(q, order, m: LogMap):
    """Joint angles (N, n) from the position columns ``q`` (columns in joint ``order``; rates and
    accelerations alike): where the ``coupling`` says its joints' encoders read motor angles
    (``angles: motor``, K x the joint angles in joint-side units once scaled), the joint angles are
    K^-1 x them."""
    case_file, fld = m.where
    cp = m.coupling
    if cp is None or cp.get("angles", "joint") != "motor":
        return q
    missing = [j for j in cp["joints"] if j not in order]
    if missing:
        raise ConfigError(f"{case_file}: field '{fld}.coupling.joints': {missing} have no position column "
                          f"(position joints {list(order)})")
    q = np.array(q, float)
    sel = [list(order).index(j) for j in cp["joints"]]
    q[:, sel] = np.linalg.solve(np.asarray(cp["matrix"], float), q[:, sel].T).T
    return q


def _mapped(cols, scale, offset, header, label, case_file, fld) -> dict:
    """``{column: its field}`` of the column map ``cols``; every mapped column must be in the files'
    ``header``, every scaled or offset one mapped."""
    mapped = {}
    for key, v in cols.items():
        for sub, c in ({None: v} if isinstance(v, str) else (v or {})).items():
            mapped.setdefault(c, f"{fld}.columns.{key}" + (f".{sub}" if sub else ""))
    for c, where in mapped.items():
        if c not in header:
            raise ConfigError(f"{case_file}: field '{where}': column {c!r} is not in {label} "
                              f"(its columns: {header})")
    for key, m in (("scale", scale), ("offset", offset)):
        for c in m:
            if c not in mapped:
                raise ConfigError(f"{case_file}: field '{fld}.{key}.{c}': column {c!r} is not mapped in columns "
                                  f"(mapped: {sorted(mapped)})")
    return mapped


def _values(tables, mapped, scale, offset, m, time_col, time_unit, case_file, fld):
    """``(values, stamps, merge report)``: each mapped column's values (minus its offset, times
    its scale), the files of one run merged on time (the stamps [s] of a merged log without a time
    column, else None; the report None for one file)."""
    rate = m.rate  # a log without a time column: row k at k / rate seconds

    def raw(tb, c, finite=True):
        v = (tb.column(c) - offset.get(c, 0.0)) * scale.get(c, 1.0)
        bad = ~np.isfinite(v)
        if finite and bad.any():
            k = tb.lines[int(np.argmax(bad))]
            raise DataError(f"{tb.path}: column {c!r} ({mapped[c]}), line {k}: empty or not finite")
        return v

    finite_ok = {m.columns.get("damping_ratio")} if m.kind == "modal" else set()
    if len(tables) == 1:
        return {c: raw(tables[0], c, c not in finite_ok) for c in mapped}, None, None
    if time_col is None and rate is None:
        raise ConfigError(f"{case_file}: field '{fld}.file': a {m.kind} data set is one file")
    parts = []
    for tb in tables:
        if time_col is None:
            own = {c: raw(tb, c) for c in mapped if c in tb.header}
            parts.append((tb.path.name, np.arange(len(tb.rows)) / rate, own))
            continue
        if time_col not in tb.header:
            raise ConfigError(f"{case_file}: field '{fld}.columns.time': column {time_col!r} is not in "
                              f"{tb.path.name}: every file of a merged data set holds the time column")
        own = {c: raw(tb, c) for c in mapped if c in tb.header and c != time_col}
        parts.append((tb.path.name, raw(tb, time_col) * TIME_UNITS[time_unit], own))
    t_m, vals, merge_report = merge_on_time(parts, f"{case_file}: {fld}")
    if time_col is None:
        return vals, t_m, merge_report
    vals[time_col] = t_m / TIME_UNITS[time_unit]
    return vals, None, merge_report


class _Columns:
    """The values of a data set's mapped columns, read by joint, each read noted as a
    :class:`Channel` (unit, source column, scale, offset)."""

    def __init__(self, vals, cols, scale, offset, label):
        self.vals, self.cols, self.scale, self.offset, self.label = vals, cols, scale, offset, label
        self.channels = {}

    def col(self, c, factor=1.0):
        return self.vals[c] * factor

    def block(self, key, order, factor=1.0):
        return np.column_stack([self.col(self.cols.get(key)[j], factor) for j in order])

    def note(self, field, j, c, unit):
        self.channels[f"{field}:{j}"] = Channel(f"{field}:{j}", unit, f"{self.label}:{c}", self.scale.get(c, 1.0),
                                                self.offset.get(c, 0.0))


def _torque_fields(v: _Columns, m: LogMap, names, t, ang) -> dict:
    """A torque log's fields: angles (and rates) of its position joints, joint torques."""
    case_file, fld = m.where
    cols = m.columns
    pk = list(cols.get("position"))
    missing = [j for j in names if j not in pk]
    if missing:
        raise ConfigError(f"{case_file}: field '{fld}.columns.position': no column for model joints {missing} "
                          f"(the model has joints {names})")
    tk = list(cols.get("torque"))
    if set(tk) == set(pk):
        torder = pk
    elif set(tk) == set(names):
        torder = names if len(pk) != len(names) else pk
    else:
        raise ConfigError(f"{case_file}: field '{fld}.columns.torque': expected a column for every model joint "
                          f"{names} (or for every position joint {pk}), got {tk}")
    for j in pk:
        v.note("q", j, cols["position"][j], "rad")
    for j in torder:
        v.note("tau", j, cols["torque"][j], "N m")
    tau = transmission(v.block("torque", torder), torder, m)
    out = {"t": t, "q": motor_angles(v.block("position", pk, ang), pk, m), "tau": tau,
           "joints": np.asarray(pk)}
    for key, name in (("velocity", "qd"), ("acceleration", "qdd")):
        if cols.get(key) is not None:
            if set(cols.get(key)) != set(pk):
                raise ConfigError(f"{case_file}: field '{fld}.columns.{key}': expected the joints of "
                                  f"columns.position {pk}, got {list(cols.get(key))}")
            out[name] = motor_angles(v.block(key, pk, ang), pk, m)
    return out


def _response_fields(v: _Columns, m: LogMap, names, t, ang) -> dict:
    """A response log's fields: applied torques at every model joint, measured channels."""
    case_file, fld = m.where
    cols = m.columns
    tk = list(cols.get("torque"))
    for j in tk:
        if j not in names:
            raise ConfigError(f"{case_file}: field '{fld}.columns.torque.{j}': unknown model joint {j!r}; "
                              f"expected one of {list(names)}")
    if set(tk) != set(names):
        raise ConfigError(f"{case_file}: field '{fld}.columns.torque': expected a column for every model joint "
                          f"{names}, got {tk}")
    ch = list(cols.get("output"))
    out = {"t": t, "tau": transmission(v.block("torque", names), names, m), "channels": np.asarray(ch),
           "y": np.column_stack([v.col(cols["output"][c], ang if c in names else 1.0) for c in ch])}
    if m.q0 is not None:
        q0 = yaml_posture(m, ang)
        if "joints" in q0:
            q0["q0"] = q0["q0"][[list(q0.pop("joints")).index(j) for j in names]]
        out.update(q0)
    elif not all(j in ch for j in names):
        raise ConfigError(f"{case_file}: field '{fld}.q0': missing (the outputs do not name every model joint "
                          f"{names}: the model is simulated from rest at q0)")
    return out


def read_csv(paths, m: LogMap) -> Record:
    """The :class:`Record` of the CSV log ``paths`` (one file, or several files of one run merged
    on time) read as the log map ``m`` says (its column map, scales, units)."""
    case_file, fld = m.where
    paths = [pathlib.Path(p) for p in (paths if isinstance(paths, (list, tuple)) else [paths])]
    tables = _tables(paths, m)
    cols, scale, offset = m.columns, m.scale or {}, m.offset or {}
    pos_unit, time_unit = m.position_unit, m.time_unit
    ang = np.pi / 180 if pos_unit == "deg" else 1.0
    names = list(m.joints)
    header = [h for tb in tables for h in tb.header]
    label = paths[0].name if len(paths) == 1 else ", ".join(p.name for p in paths)
    mapped = _mapped(cols, scale, offset, header, label, case_file, fld)
    time_col = cols.get("time") if m.kind != "modal" else None
    vals, t_rows, merge_report = _values(tables, mapped, scale, offset, m, time_col, time_unit, case_file, fld)
    v = _Columns(vals, cols, scale, offset, label)
    conditioning = {"merge": merge_report} if merge_report else {}
    if m.kind == "modal":
        out = yaml_posture(m, ang)
        out.update(freq=v.col(cols.get("frequency")), zeta=v.col(cols.get("damping_ratio")))
        return Record(out, v.channels, conditioning)
    if time_col is None:
        t = np.arange(len(tables[0].rows)) / m.rate if len(tables) == 1 else t_rows
    else:
        t = v.col(time_col, TIME_UNITS[time_unit])
    if m.kind == "torque":
        return Record(_torque_fields(v, m, names, t, ang), v.channels, conditioning)
    return Record(_response_fields(v, m, names, t, ang), v.channels, conditioning)


def csv_arrays(path, m: LogMap) -> dict:
    """The NPZ fields of the CSV log ``path`` (:func:`read_csv` without the metadata)."""
    return read_csv(path, m).arrays
