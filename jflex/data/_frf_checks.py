"""The fields of the frequency-domain data sets checked: a posture's angles, a measured FRF (and its
repeats), a modal table (natural frequencies, damping ratios, mode shapes)."""

from __future__ import annotations

import numpy as np

from .._errors import DataError
from ._fields import joint_columns, numeric_field


def posture_arrays(arrs, path, joint_names):
    """``(q0 of the model joints, q0 of the extra joints, their names)`` of a posture's data set."""
    if "q0" not in arrs:
        raise DataError(f"{path}: field 'q0': missing (the posture (n,) [rad] of the measurement)")
    q0 = numeric_field(arrs["q0"], path, "q0", ndim=1)
    idx, extra, names = joint_columns(arrs, path, joint_names, "q0", q0.size)
    return q0[idx], q0[extra], names


def frf_arrays(arrs, path, joint_names):
    """An FRF data set's arrays checked (``q0``, ``freq`` [Hz], ``H`` (F, 3, 3), ``H_repeats``):
    ``(arrays, extra joint names)``."""
    q0, q0x, names = posture_arrays(arrs, path, joint_names)
    for k in ("freq", "H"):
        if k not in arrs:
            raise DataError(f"{path}: field '{k}': missing (an frf data set needs q0, freq (F,) [Hz], H (F, 3, 3))")
    f = numeric_field(arrs["freq"], path, "freq", ndim=1)
    if f.size == 0:
        raise DataError(f"{path}: field 'freq': empty; expected at least one frequency line")
    if np.any(f <= 0) or np.any(np.diff(f) <= 0):
        raise DataError(f"{path}: field 'freq': frequencies must be > 0 Hz and strictly increasing")
    H = numeric_field(arrs["H"], path, "H", ndim=3, complex_ok=True)
    if H.shape != (f.size, 3, 3):
        raise DataError(f"{path}: field 'H': expected shape ({f.size}, 3, 3) (freq x output x input), got {H.shape}")
    out = {"q0": q0, "q0_extra": q0x, "freq": f, "H": H.astype(complex)}
    if "H_repeats" in arrs:
        r = numeric_field(arrs["H_repeats"], path, "H_repeats", ndim=4, complex_ok=True).astype(complex)
        if r.shape[1:] != H.shape or r.shape[0] < 2:
            raise DataError(f"{path}: field 'H_repeats': expected shape (R, {f.size}, 3, 3) with R >= 2 repeats of H, "
                            f"got {r.shape}")
        out["H_repeats"] = r
    return out, names


def modal_arrays(arrs, path, joint_names):
    """A modal table's arrays checked (``q0``, ``freq`` [Hz], ``zeta``, ``shapes``): ``(arrays,
    extra joint names)``."""
    q0, q0x, names = posture_arrays(arrs, path, joint_names)
    for k in ("freq", "zeta"):
        if k not in arrs:
            raise DataError(f"{path}: field '{k}': missing (a modal data set needs q0, freq (M,) [Hz], zeta (M,))")
    f = numeric_field(arrs["freq"], path, "freq", ndim=1)
    if f.size == 0:
        raise DataError(f"{path}: field 'freq': the modal table is empty; expected at least one mode")
    z = numeric_field(arrs["zeta"], path, "zeta", ndim=1, allow_nan=True)
    if np.any(f <= 0):
        raise DataError(f"{path}: field 'freq': natural frequencies must be > 0 Hz")
    if z.shape != f.shape:
        raise DataError(f"{path}: field 'zeta': expected shape {f.shape} (one ratio per mode), got {z.shape}")
    if np.any(z[~np.isnan(z)] < 0) or np.any(z[~np.isnan(z)] >= 1):  # NaN: not measured; +-inf is refused
        raise DataError(f"{path}: field 'zeta': damping ratios must lie in [0, 1) (a ratio, not a percentage)")
    out = {"q0": q0, "q0_extra": q0x, "freq": f, "zeta": z}
    if "shapes" in arrs:
        s = numeric_field(arrs["shapes"], path, "shapes", ndim=2, complex_ok=True)
        if s.shape[1] != f.size:
            raise DataError(f"{path}: field 'shapes': expected (s, {f.size}) (one column per mode), got {s.shape}")
        out["shapes"] = s
    return out, names
