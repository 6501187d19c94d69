"""CSV data sets: a log plus the column map case.yaml gives for it, read into the arrays an NPZ
data set holds (``t``, ``q``, ``tau``, ...); the case loader then checks them like any NPZ.

Only the mapped columns are parsed (a log may carry text columns besides). Each value is the raw
cell times its ``scale`` factor (e.g. motor current [A] x torque constant x gear ratio), in the
units ``units`` names (time s or ms; angles rad or deg), converted to SI here.
"""

from __future__ import annotations

import csv
import pathlib

import numpy as np

from .._errors import ConfigError, DataError
from ._case import yaml_posture
from ._schema import Units

DELIMITERS = {",": ",", ";": ";", "tab": "\t", "space": None}


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
        if sniff and delimiter is None:
            counts = {d: lines[0][1].count(d) for d in (",", ";", "\t")}
            best = max(counts, key=counts.get)
            delimiter = best if counts[best] else None
        if delimiter is None:
            cells = [s.split() for _, s in lines]
        else:
            cells = list(csv.reader((s for _, s in lines), delimiter=delimiter))
        self.header = [h.strip() for h in cells[0]]
        if any(not h for h in self.header):
            raise DataError(f"{path}: line {lines[0][0]}: the header has an empty column name ({self.header})")
        dup = sorted({h for h in self.header if self.header.count(h) > 1})
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
            return np.asarray(cells, dtype=float)
        except ValueError:
            for k, c in zip(self.lines, cells):
                try:
                    float(c)
                except ValueError:
                    raise DataError(f"{self.path}: column {name!r}, line {k}: expected a number, got {c!r}") from None
            raise


def csv_arrays(path: pathlib.Path, spec, robot, case_file, fld: str) -> dict:
    """The NPZ fields of the CSV data set ``spec`` (a validated ``datasets[i]`` of case.yaml)."""
    if not path.is_file():
        raise ConfigError(f"{case_file}: field '{fld}.file': data file {path} not found")
    table = Table(path, DELIMITERS[spec.delimiter] if spec.delimiter else None, sniff=spec.delimiter is None)
    cols, scale, units = spec.columns, spec.scale or {}, spec.units or Units()
    ang = np.pi / 180 if units.position == "deg" else 1.0
    names = list(robot.joint_names)

    mapped = {}  # column -> its field in case.yaml
    for key in type(cols).model_fields:
        v = getattr(cols, key)
        for sub, c in ({None: v} if isinstance(v, str) else (v or {})).items():
            mapped.setdefault(c, f"{fld}.columns.{key}" + (f".{sub}" if sub else ""))
    for c, where in mapped.items():
        if c not in table.header:
            raise ConfigError(f"{case_file}: field '{where}': column {c!r} is not in {path.name} "
                              f"(its columns: {table.header})")
    for c in scale:
        if c not in mapped:
            raise ConfigError(f"{case_file}: field '{fld}.scale.{c}': column {c!r} is not mapped in columns "
                              f"(mapped: {sorted(mapped)})")

    def col(c, factor=1.0, finite=True):
        v = table.column(c) * scale.get(c, 1.0) * factor
        bad = ~np.isfinite(v)
        if finite and bad.any():
            k = table.lines[int(np.argmax(bad))]
            raise DataError(f"{path}: column {c!r} ({mapped[c]}), line {k}: empty or not finite")
        return v

    def block(key, order, factor=1.0):
        return np.column_stack([col(getattr(cols, key)[j], factor) for j in order])

    def keys_as(key, allowed, what):
        got = list(getattr(cols, key))
        for j in got:
            if j not in allowed:
                raise ConfigError(f"{case_file}: field '{fld}.columns.{key}.{j}': unknown {what} {j!r}; "
                                  f"expected one of {list(allowed)}")
        return got

    if spec.kind == "modal":
        out = yaml_posture(spec, robot, case_file, fld, ang)
        out.update(freq=col(cols.frequency), zeta=col(cols.damping_ratio, finite=False))
        return out
    t = col(cols.time, 1e-3 if units.time == "ms" else 1.0)
    if spec.kind == "torque":
        pk = list(cols.position)
        missing = [j for j in names if j not in pk]
        if missing:
            raise ConfigError(f"{case_file}: field '{fld}.columns.position': no column for model joints {missing} "
                              f"(the model has joints {names})")
        tk = list(cols.torque)
        if set(tk) == set(pk):
            torder = pk
        elif set(tk) == set(names):
            torder = names if len(pk) != len(names) else pk
        else:
            raise ConfigError(f"{case_file}: field '{fld}.columns.torque': expected a column for every model joint "
                              f"{names} (or for every position joint {pk}), got {tk}")
        out = {"t": t, "q": block("position", pk, ang), "tau": block("torque", torder), "joints": np.asarray(pk)}
        for key, name in (("velocity", "qd"), ("acceleration", "qdd")):
            if getattr(cols, key) is not None:
                if set(getattr(cols, key)) != set(pk):
                    raise ConfigError(f"{case_file}: field '{fld}.columns.{key}': expected the joints of "
                                      f"columns.position {pk}, got {list(getattr(cols, key))}")
                out[name] = block(key, pk, ang)
        return out
    # response: applied torques at every model joint, measured channels
    tk = keys_as("torque", names, "model joint")
    if set(tk) != set(names):
        raise ConfigError(f"{case_file}: field '{fld}.columns.torque': expected a column for every model joint "
                          f"{names}, got {tk}")
    ch = list(cols.output)
    out = {"t": t, "tau": block("torque", names), "channels": np.asarray(ch),
           "y": np.column_stack([col(cols.output[c], ang if c in names else 1.0) for c in ch])}
    if spec.q0 is not None:
        q0 = yaml_posture(spec, robot, case_file, fld, ang)
        if "joints" in q0:
            q0["q0"] = q0["q0"][[list(q0.pop("joints")).index(j) for j in names]]
        out.update(q0)
    elif not all(j in ch for j in names):
        raise ConfigError(f"{case_file}: field '{fld}.q0': missing (the outputs do not name every model joint "
                          f"{names}: the model is simulated from rest at q0)")
    return out
