"""Universal File Format dataset 58 (function at nodal DOF): the ASCII records that EMA
software (LMS Test.Lab, ME'scope, ...) exports FRFs in, and the FRF data set of a case read from
them (the records of one response point and one reference point, in the three translations each,
gathered into the tool receptance ``H`` (F, 3, 3), output x input).

One reader serves identification and the gap diagnosis. It is not taken from ``pyuff`` (PyPI):
only ASCII dataset 58 is needed, every malformed record must raise :class:`jflex.DataError`
naming the file, the line and the record, and a dependency for ~100 lines of fixed-format
parsing, whose own exceptions would still have to be translated into such messages, was not
judged worth it.
"""

from __future__ import annotations

import os
import pathlib
from typing import NamedTuple

import numpy as np

from .._errors import ConfigError, DataError
from ._log_map import LogMap
from ._posture import yaml_posture

_ORDINATE = {2: (False, "single"), 4: (False, "double"), 5: (True, "single"), 6: (True, "double")}
FUNCTION_TYPES = {0: "general", 1: "time response", 2: "auto spectrum", 3: "cross spectrum", 4: "frequency response function",
                  5: "transmissibility", 6: "coherence", 9: "power spectral density"}


class UFF58(NamedTuple):
    """One dataset 58.

    ``x`` (N,) abscissa (Hz for FRFs); ``data`` (N,) real or complex; ``function_type`` (4: FRF);
    ``response`` / ``reference``: (node, direction) (direction 1..3 = +X..+Z, -1..-3 negative,
    4..6 rotations); ``id_lines`` the five header lines; ``units`` (abscissa, numerator,
    denominator) labels as written.
    """

    x: np.ndarray
    data: np.ndarray
    function_type: int
    response: tuple
    reference: tuple
    id_lines: tuple
    units: tuple


def _ints(line, widths):
    out, k = [], 0
    for w in widths:
        out.append(line[k : k + w])
        k += w
    return out


def _parse_one(lines, src, start):
    where = f"{src}: dataset 58 starting at line {start + 1}"
    if len(lines) < 12:
        raise DataError(f"{where}: truncated (expected at least 11 header records, got {len(lines)} lines)")
    ids = tuple(l.rstrip() for l in lines[:5])
    l6 = lines[5].rstrip()
    try:
        if len(l6) >= 80:  # Format(2(I5,I10),2(1X,10A1,I10,I4)): blank entity names are allowed
            ftype = int(l6[0:5])
            resp = (int(l6[41:51]), int(l6[51:55]))
            ref = (int(l6[66:76]), int(l6[76:80]))
        else:
            r6 = l6.split()
            ftype, resp, ref = int(r6[0]), (int(r6[5]), int(r6[6])), (int(r6[8]), int(r6[9]))
    except (IndexError, ValueError):
        raise DataError(f"{where}: record 6 (function type, nodes, directions) is malformed: '{lines[5].rstrip()}'") from None
    r7 = lines[6].split()
    try:
        otype, n, even = int(r7[0]), int(r7[1]), int(r7[2])
        x0, dx = float(r7[3].replace("D", "E")), float(r7[4].replace("D", "E"))
    except (IndexError, ValueError):
        raise DataError(f"{where}: record 7 (data type, number of points, spacing) is malformed: '{lines[6].rstrip()}'") from None
    if otype not in _ORDINATE:
        raise DataError(f"{where}: ordinate data type {otype} not supported (expected 2, 4 real or 5, 6 complex)")
    units = tuple(l[41:61].strip() for l in lines[7:10])  # Format(I10,3I5,2(1X,20A1)): the unit label
    vals = []
    for l in lines[11:]:
        try:
            vals += [float(v.replace("D", "E")) for v in l.split()]
        except ValueError:
            raise DataError(f"{where}: data record is not numeric: '{l.rstrip()}'") from None
    is_complex, _ = _ORDINATE[otype]
    per = (2 if is_complex else 1) + (0 if even else 1)
    if len(vals) != per * n:
        raise DataError(f"{where}: record 7 announces {n} points ({per * n} numbers) but the data record holds {len(vals)}")
    v = np.asarray(vals).reshape(n, per)
    if even:
        x = x0 + dx * np.arange(n)
        d = v[:, 0] + 1j * v[:, 1] if is_complex else v[:, 0]
    else:
        x = v[:, 0]
        d = v[:, 1] + 1j * v[:, 2] if is_complex else v[:, 1]
    if not np.isfinite(d).all():
        raise DataError(f"{where}: data contains NaN/inf")
    return UFF58(x, d, ftype, resp, ref, ids, units)


def read_uff58(path: str | os.PathLike) -> list[UFF58]:
    """Read every ASCII dataset 58 of a universal file (other datasets are skipped).

    **Returns:** list of :class:`UFF58`. A binary dataset (58b) or a malformed record raises
    :class:`jflex.DataError` naming the file and the record.
    """
    path = pathlib.Path(path)
    if not path.is_file():
        raise DataError(f"{path}: universal file not found")
    lines = path.read_text(errors="replace").splitlines()
    out, i = [], 0
    while i < len(lines):
        if lines[i].strip() == "-1" and i + 1 < len(lines):
            tag = lines[i + 1].strip()
            j = i + 2
            while j < len(lines) and lines[j].strip() != "-1":
                j += 1
            if tag.split()[0:1] == ["58b"]:
                raise DataError(f"{path}: line {i + 2}: binary dataset 58b is not supported; export ASCII UFF 58")
            if tag == "58":
                out.append(_parse_one(lines[i + 2 : j], str(path), i + 2))
            i = j + 1
        else:
            i += 1
    if not out:
        raise DataError(f"{path}: no dataset 58 found (a UFF file has blocks between '    -1' delimiters)")
    return out


def write_uff58(path: str | os.PathLike, freq, H, *, response=(1, 3), reference=(1, 3), name: str = "FRF",
                units=("Hz", "m", "N")) -> None:
    """Write one complex FRF on an even frequency grid as ASCII dataset 58 (double precision)."""
    freq = np.asarray(freq, float)
    H = np.asarray(H, complex)
    if freq.shape != H.shape or freq.ndim != 1:
        raise DataError(f"write_uff58: freq and H must be 1-D of equal length, got {freq.shape} and {H.shape}")
    dx = freq[1] - freq[0]
    if not np.allclose(np.diff(freq), dx, rtol=1e-9):
        raise DataError("write_uff58: freq must be evenly spaced")
    L = ["    -1", "    58", name[:80], "NONE", "NONE", "NONE", "NONE",
         f"{4:5d}{1:10d}{1:5d}{0:10d} {'NONE':10s}{response[0]:10d}{response[1]:4d} {'NONE':10s}{reference[0]:10d}{reference[1]:4d}",
         f"{6:10d}{len(freq):10d}{1:10d}{freq[0]:13.5E}{dx:13.5E}{0.0:13.5E}",
         f"{18:10d}{0:5d}{0:5d}{0:5d} {'Frequency':20s} {units[0]:20s}",
         f"{8:10d}{0:5d}{0:5d}{0:5d} {'Displacement':20s} {units[1]:20s}",
         f"{13:10d}{0:5d}{0:5d}{0:5d} {'Force':20s} {units[2]:20s}",
         f"{0:10d}{0:5d}{0:5d}{0:5d} {'NONE':20s} {'NONE':20s}"]
    vals = np.column_stack([H.real, H.imag]).ravel()
    for k in range(0, len(vals), 4):
        L.append("".join(f"{v:20.12E}" for v in vals[k : k + 4]))
    L.append("    -1")
    pathlib.Path(path).write_text("\n".join(L) + "\n")

FRF_FUNCTION = 4  # UFF 58 function type of a frequency response function
# numerator unit labels of the FRF's output quantity
QUANTITY_UNITS = {"m": "receptance", "m/s": "mobility", "m/s^2": "accelerance", "m/s2": "accelerance",
                  "m/s**2": "accelerance"}
AXES = "XYZ"


def uff_arrays(path: pathlib.Path, m: LogMap) -> dict:
    """The NPZ fields (``q0``, ``freq``, ``H``) of the UFF frf data set ``path`` (its posture and
    quantity from the log map ``m``)."""
    case_file, fld = m.where
    if not path.is_file():
        raise ConfigError(f"{case_file}: field '{fld}.file': data file {path} not found")
    recs = [r for r in read_uff58(path) if r.function_type == FRF_FUNCTION]
    if not recs:
        raise DataError(f"{path}: no dataset 58 of function type 4 (FRF)")
    nodes = {(r.response[0], r.reference[0]) for r in recs}
    if len(nodes) != 1:
        raise DataError(f"{path}: records of several (response, reference) node pairs {sorted(nodes)}: a tool FRF "
                        "set has one response and one reference point (split the file)")
    freq = recs[0].x
    H = np.full((freq.size, 3, 3), np.nan, complex)
    seen = {}
    for k, r in enumerate(recs):
        (_, do), (_, di) = r.response, r.reference
        if not (1 <= abs(do) <= 3 and 1 <= abs(di) <= 3):
            raise DataError(f"{path}: record {k + 1}: directions ({do}, {di}): only translations (+-1..3) enter "
                            "the tool receptance")
        o, i = abs(do) - 1, abs(di) - 1
        if (o, i) in seen:
            raise DataError(f"{path}: records {seen[(o, i)] + 1} and {k + 1} both hold H[{AXES[o]}, {AXES[i]}]")
        if r.x.shape != freq.shape or not np.allclose(r.x, freq, rtol=1e-9, atol=0):
            raise DataError(f"{path}: record {k + 1}: its frequencies differ from record 1's (one grid expected)")
        quantity = m.quantity or QUANTITY_UNITS.get(r.units[1].replace(" ", "").lower())
        if quantity is None:
            raise DataError(f"{path}: record {k + 1}: output unit {r.units[1]!r} is not one of {list(QUANTITY_UNITS)}; "
                            f"convert to SI or state the quantity in case.yaml ({fld}.quantity)")
        seen[(o, i)] = k
        h = np.sign(do) * np.sign(di) * r.data
        if quantity != "receptance":
            if np.any(freq <= 0):
                raise DataError(f"{path}: field 'freq': the {quantity} is converted to receptance by (i 2 pi f)^-"
                                f"{1 if quantity == 'mobility' else 2}: frequencies must be > 0 Hz")
            h = h / (2j * np.pi * freq) ** (1 if quantity == "mobility" else 2)
        H[:, o, i] = h
    missing = [f"H[{AXES[o]}, {AXES[i]}]" for o in range(3) for i in range(3) if (o, i) not in seen]
    if missing:
        raise DataError(f"{path}: no record for {missing}: a tool FRF set holds the 3 x 3 translations "
                        "(response X/Y/Z x reference X/Y/Z)")
    return {**yaml_posture(m), "freq": freq, "H": H}
