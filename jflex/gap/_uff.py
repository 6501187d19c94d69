"""FRF data sets as UFF 58 files (what EMA software exports): the records of one response point
and one reference point, in the three translations each, gathered into the tool receptance
``H`` (F, 3, 3) (output x input) an NPZ frf data set holds; the posture comes from case.yaml."""

from __future__ import annotations

import pathlib

import numpy as np

from .._errors import ConfigError, DataError
from ..identify import read_uff58
from ._case import yaml_posture

FRF_FUNCTION = 4  # UFF 58 function type of a frequency response function
# numerator unit labels of the FRF's output quantity
QUANTITY_UNITS = {"m": "receptance", "m/s": "mobility", "m/s^2": "accelerance", "m/s2": "accelerance",
                  "m/s**2": "accelerance"}
AXES = "XYZ"


def uff_arrays(path: pathlib.Path, spec, robot, case_file, fld: str) -> dict:
    """The NPZ fields (``q0``, ``freq``, ``H``) of the UFF frf data set ``spec``."""
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
        quantity = spec.quantity or QUANTITY_UNITS.get(r.units[1].replace(" ", "").lower())
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
    return {**yaml_posture(spec, robot, case_file, fld), "freq": freq, "H": H}
