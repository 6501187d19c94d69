"""Validating measured arrays before anything is traced: finite values, time axes, lengths, shapes.

Every check raises :class:`jflex.DataError` naming the file and the field at fault and what is
expected, so a bad file never turns into a silent NaN deep inside a fit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .._errors import DataError


def _where(source, field):
    return f"{source}: field '{field}'" if source else f"field '{field}'"


def check_finite(x, field: str, source: str | None = None) -> np.ndarray:
    """Return ``x`` as an array; a :class:`DataError` if it holds NaN or inf (first bad index named)."""
    a = np.asarray(x)
    if not np.issubdtype(a.dtype, np.number):
        raise DataError(f"{_where(source, field)}: expected numbers, got dtype {a.dtype}")
    bad = ~np.isfinite(a)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise DataError(
            f"{_where(source, field)}: contains {int(bad.sum())} NaN/inf value(s), the first at index {idx}; "
            "remove or interpolate them before identification"
        )
    return a


def check_time(t, field: str = "t", source: str | None = None, *, uniform: bool = False, rtol: float = 1e-6) -> np.ndarray:
    """Validate a time axis: 1-D, finite, strictly increasing, and evenly spaced when ``uniform``.

    **Arguments:** ``t`` (N,) [s]; ``uniform``: the caller needs a constant step (FFT-based
    processing); ``rtol``: allowed relative spread of the step.

    **Returns:** ``t`` as a float array.
    """
    t = check_finite(t, field, source).astype(float)
    if t.ndim != 1 or t.size < 2:
        raise DataError(f"{_where(source, field)}: expected a 1-D time axis with at least 2 samples, got shape {t.shape}")
    dt = np.diff(t)
    if (dt <= 0).any():
        k = int(np.argmax(dt <= 0))
        raise DataError(
            f"{_where(source, field)}: time must be strictly increasing, but t[{k + 1}] = {t[k + 1]} "
            f"<= t[{k}] = {t[k]}"
        )
    if uniform:
        mean = dt.mean()
        dev = np.abs(dt - mean).max()
        if dev > rtol * mean:
            k = int(np.argmax(np.abs(dt - mean)))
            raise DataError(
                f"{_where(source, field)}: uniform sampling is required here, but the step varies "
                f"(dt[{k}] = {dt[k]:.6g} s vs mean {mean:.6g} s); resample onto an even grid first"
            )
    return t


def check_lengths(arrays: Mapping[str, np.ndarray], source: str | None = None, axis: int = 0) -> int:
    """All arrays must share their length along ``axis``; returns that length."""
    lengths = {k: np.shape(v)[axis] if np.ndim(v) > axis else None for k, v in arrays.items()}
    ref_name, ref = next(iter(lengths.items()))
    for k, n in lengths.items():
        if n != ref:
            raise DataError(
                f"{_where(source, k)}: has {n} samples along axis {axis} but '{ref_name}' has {ref}; "
                "all signals of one record must have the same length"
            )
    return int(ref)


def check_shape(x, shape: Sequence[int | None], field: str, source: str | None = None) -> np.ndarray:
    """``x`` must match ``shape`` (``None`` = any size in that axis)."""
    a = np.asarray(x)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise DataError(f"{_where(source, field)}: expected shape {want}, got {a.shape}")
    return a
