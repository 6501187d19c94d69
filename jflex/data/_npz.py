"""NPZ data sets: the fields of an archive as they are (numeric or string arrays; pickles refused).

An NPZ file is a zip archive of ``.npy`` members. Only the fields a data set uses are read, and
each is refused by the size its own ``.npy`` header declares (shape x item size) before a byte of
its data is decompressed: an archive whose unused member would inflate to gigabytes costs
nothing, and a used one that large is named instead of filling the memory.
"""

from __future__ import annotations

import pathlib
import zipfile

import numpy as np
from numpy.lib import format as npy_format

from .._errors import ConfigError, DataError
from ._record import Record, channels_of

# the largest field read (decompressed): 1 GiB holds 10^7 samples of 13 joints with ten repeats
MAX_FIELD_BYTES = 1 << 30
_NPY_MAGIC = b"\x93NUMPY"


def _header(fp, where):
    """``(shape, dtype)`` declared by the ``.npy`` header at the start of ``fp``."""
    try:
        major, _ = npy_format.read_magic(fp)
        read = {1: npy_format.read_array_header_1_0, 2: npy_format.read_array_header_2_0}.get(major)
        if read is None:
            raise ValueError(f"unknown .npy format version {major}")
        shape, _, dtype = read(fp)
    except Exception as exc:  # a member that is no .npy array
        raise DataError(f"{where}: not a valid .npy array ({exc})") from None
    return shape, dtype


def load_npz_fields(path: pathlib.Path, field: str, case_file, keys=None) -> dict:
    """The fields ``keys`` (default: every field) of the NPZ archive ``path`` (named in ``field``
    of ``case_file``); a key the archive lacks is left out (the caller names what it needs)."""
    if not path.is_file():
        raise ConfigError(f"{case_file}: field '{field}': data file {path} not found")
    try:
        with open(path, "rb") as f:
            head = f.read(len(_NPY_MAGIC))
    except OSError as exc:
        raise DataError(f"{case_file}: field '{field}': {path.name} cannot be read ({exc.strerror})") from None
    if head == _NPY_MAGIC:
        raise DataError(f"{case_file}: field '{field}': {path.name} is a single .npy array, not an NPZ archive of fields")
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise DataError(f"{case_file}: field '{field}': {path.name} is not a valid NPZ file (an NPZ file is a zip "
                        f"archive of .npy arrays, as numpy.savez writes it; {exc})") from None
    out = {}
    with zf:
        members = {n[:-4]: n for n in zf.namelist() if n.endswith(".npy")}
        for k in members if keys is None else [k for k in keys if k in members]:
            where = f"{path}: field '{k}'"
            info = zf.getinfo(members[k])
            try:
                with zf.open(info) as fp:
                    shape, dtype = _header(fp, where)
                    if dtype.hasobject:
                        raise DataError(f"{where}: holds Python objects (dtype {dtype}), which jflex does not read "
                                        "(loading them would run code); expected numeric or string arrays")
                    size = int(np.prod(shape, dtype=object)) * dtype.itemsize
                    if size > MAX_FIELD_BYTES:
                        raise DataError(f"{where}: declares shape {shape} of {dtype} ({size / 2**30:.3g} GiB); expected "
                                        f"at most {MAX_FIELD_BYTES / 2**30:g} GiB per field")
                with zf.open(info) as fp:
                    out[k] = npy_format.read_array(fp, allow_pickle=False)
            except DataError:
                raise
            except Exception as exc:  # a torn member: its data end before its header's shape
                raise DataError(f"{where}: not readable ({type(exc).__name__}: {exc}); fields are numeric or "
                                "string arrays") from None
    return out


def read_npz(path: pathlib.Path, field: str, case_file, keys=None) -> Record:
    """The :class:`Record` of an NPZ data set: its fields (``keys`` only, when given), channels
    named by its ``joints`` array."""
    arrs = load_npz_fields(path, field, case_file, keys)
    names = None
    if "joints" in arrs:
        names = [str(s) for s in np.asarray(arrs["joints"]).ravel()]
    return Record(arrs, channels_of(arrs, path.name, names))
