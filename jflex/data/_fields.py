"""The fields of a measured data set checked one by one: numbers of the expected rank, finite,
and columns matched to a model's joints by name."""

from __future__ import annotations

import numpy as np

from .._errors import DataError


def numeric_field(arr, path, field, *, ndim=None, complex_ok=False, allow_nan=False):
    """The field ``field`` of the data file ``path`` as a float (or complex) array: numbers only,
    ``ndim`` dimensions when given, finite unless ``allow_nan``, and no magnitude whose square
    overflows."""
    a = np.asarray(arr)
    if not (np.issubdtype(a.dtype, np.number)) or (np.iscomplexobj(a) and not complex_ok):
        raise DataError(f"{path}: field '{field}': expected {'complex ' if complex_ok else 'real '}numbers, got dtype {a.dtype}")
    if ndim is not None and a.ndim != ndim:
        raise DataError(f"{path}: field '{field}': expected {ndim} dimension(s), got shape {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any() and not allow_nan:
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise DataError(f"{path}: field '{field}': contains NaN/inf, the first at index {idx}")
    # finite values whose squares overflow: every gap measure sums squares (a relative RMS), which
    # would turn inf and the gap NaN
    fin = np.abs(a[~bad]) if bad.any() else np.abs(a)
    if fin.size:
        with np.errstate(over="ignore"):
            energy = float(np.sum(np.square(fin)))
        if not np.isfinite(energy):
            raise DataError(f"{path}: field '{field}': magnitudes up to {float(fin.max()):.3g} overflow the squared "
                            "sums of the gap measures; expected values in SI units (a unit or scale slip?)")
    return a.astype(complex if np.iscomplexobj(a) else float)


def joint_columns(arrs, path, joint_names, width_field: str, width: int):
    """Map data columns to model joints ``joint_names`` with the optional ``joints`` name array:
    ``(column of each model joint, extra columns, their names)``."""
    names = tuple(joint_names)
    if "joints" in arrs:
        jn = tuple(str(s) for s in np.asarray(arrs["joints"]).ravel())
        if len(jn) != width:
            raise DataError(f"{path}: field 'joints': {len(jn)} names but '{width_field}' has {width} columns")
        missing = [j for j in names if j not in jn]
        if missing:
            raise DataError(f"{path}: field 'joints': model joints {missing} are not in the data (joints {list(jn)})")
        idx = [jn.index(j) for j in names]
        extra = [i for i in range(width) if jn[i] not in names]
        return idx, extra, tuple(jn[i] for i in extra)
    if width != len(names):
        raise DataError(
            f"{path}: field '{width_field}': {width} columns but the model has {len(names)} joints {list(names)}; "
            "add a 'joints' array naming each column when the data records more joints"
        )
    return list(range(width)), [], ()
