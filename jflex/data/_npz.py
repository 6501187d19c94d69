"""NPZ data sets: the fields of an archive as they are (numeric or string arrays; pickles refused)."""

from __future__ import annotations

import pathlib

import numpy as np

from .._errors import ConfigError, DataError
from ._record import Record, channels_of


def load_npz_fields(path: pathlib.Path, field: str, case_file) -> dict:
    """Every field of the NPZ archive ``path`` (named in ``field`` of ``case_file``)."""
    if not path.is_file():
        raise ConfigError(f"{case_file}: field '{field}': data file {path} not found")
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as exc:  # a torn or non-NPZ file
        raise DataError(f"{case_file}: field '{field}': {path.name} is not a readable NPZ file "
                        f"({type(exc).__name__}: {exc})") from None
    if not hasattr(z, "files"):  # a bare .npy array
        raise DataError(f"{case_file}: field '{field}': {path.name} is a single .npy array, not an NPZ archive of fields")
    out = {}
    with z:
        for k in z.files:
            try:
                out[k] = z[k]
            except Exception as exc:  # object arrays (pickles) are refused, or a torn member
                raise DataError(f"{path}: field '{k}': not readable ({type(exc).__name__}: {exc}); "
                                "fields are numeric or string arrays") from None
    return out


def read_npz(path: pathlib.Path, field: str, case_file) -> Record:
    """The :class:`Record` of an NPZ data set: its fields, channels named by its ``joints`` array."""
    arrs = load_npz_fields(path, field, case_file)
    names = None
    if "joints" in arrs:
        names = [str(s) for s in np.asarray(arrs["joints"]).ravel()]
    return Record(arrs, channels_of(arrs, path.name, names))
