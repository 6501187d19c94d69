"""NPZ data sets: the fields of an archive as they are (numeric or string arrays; pickles refused).

An NPZ file is a zip archive of ``.npy`` members. Only the fields a data set uses are read, and
each is refused by the size its own ``.npy`` header declares (shape x item size) before a byte of
its data is decompressed: an archive whose unused member would inflate to gigabytes costs
nothing, and a used one that large is named instead of filling the memory.

:func:`load_npz` is the identification's strict form: named fields, each finite and as long as
the time axis, the time axis strictly increasing (and evenly spaced when asked).
"""

from __future__ import annotations

import os
import pathlib
import zipfile
from collections.abc import Sequence

import numpy as np
from numpy.lib import format as npy_format

from .._errors import ConfigError, DataError
from ._record import Record, channels_of
from ._validate import check_finite, check_lengths, check_time

# the fields each kind of NPZ data set may hold (docs/case_format.md): only these are read
NPZ_KEYS = {"torque": ("t", "q", "tau", "qd", "qdd", "tau_repeats", "joints"),
            "frf": ("q0", "freq", "H", "H_repeats", "joints"),
            "modal": ("q0", "freq", "zeta", "shapes", "joints"),
            "response": ("t", "tau", "y", "channels", "q0", "y_repeats")}
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


def load_npz(
    path: str | os.PathLike,
    fields: Sequence[str],
    *,
    time: str | None = "t",
    uniform: bool = False,
    optional: Sequence[str] = (),
) -> dict[str, np.ndarray]:
    """Load an NPZ data file and validate it.

    **Arguments:**

    - ``path``: the ``.npz`` file.
    - ``fields``: required arrays; each must be finite and have as many samples (axis 0) as the
      time axis.
    - ``time``: name of the time field [s] (checked strictly increasing), or ``None``.
    - ``uniform``: require an even time step (FFT filtering, spectral differentiation, FRFs).
    - ``optional``: fields checked the same way when present.

    **Returns:** dict field -> float array.
    """
    path = pathlib.Path(path)
    src = str(path)
    if not path.is_file():
        raise DataError(f"{src}: data file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            raw = {k: np.asarray(z[k]) for k in z.files}
    except Exception as exc:  # numpy raises several types for a corrupt archive
        raise DataError(f"{src}: not a readable NPZ archive ({exc})") from None
    want = ([time] if time else []) + list(fields)
    missing = [k for k in want if k not in raw]
    if missing:
        raise DataError(f"{src}: missing field(s) {missing}; the file has {sorted(raw)}")
    out = {}
    if time:
        out[time] = check_time(raw[time], time, src, uniform=uniform)
    for k in list(fields) + [k for k in optional if k in raw]:
        out[k] = check_finite(raw[k], k, src).astype(float if not np.iscomplexobj(raw[k]) else complex)
    if time:
        check_lengths({time: out[time], **{k: out[k] for k in out if k != time}}, src)
    return out
