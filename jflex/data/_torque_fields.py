"""A torque data set's fields checked and conditioned: angles, torques and any logged rates in the
model's joint order, stamps made uniform and channels judged (:func:`jflex.data.condition_torque`),
a log with gaps too long to bridge cut into stretches, missing derivatives filled in."""

from __future__ import annotations

import numpy as np

from .._errors import DataError
from ._condition import condition_torque, split_at_gaps
from ._fields import joint_columns, numeric_field

MIN_WINDOW_SAMPLES = 20  # a torque record shorter than this is refused


def torque_arrays(arrs, path, joint_names, options=None, *, split: bool = False):
    """The torque data set's arrays in the order of the model joints ``joint_names``, conditioned (:func:`jflex.data.condition_torque`:
    stamps made uniform, torque channels checked). **Returns** ``(arrays, extra joints, report,
    excluded joints)``.

    With ``split``, a log with gaps too long to bridge is cut at them
    (:func:`jflex.data._condition.split_at_gaps`) and each stretch conditioned on its own:
    **returns** ``(stretches, split report, extra joints)``, ``stretches`` a list in time order of
    ``((start_s, end_s, raw rows) or None, (arrays, report, excluded) or None)`` (None: a stretch
    under ``MIN_WINDOW_SAMPLES`` rows; a log without such gaps is one stretch, ``(None, ...)``,
    and the report None)."""
    options = options or {}
    for k in ("t", "q", "tau"):
        if k not in arrs:
            raise DataError(f"{path}: field '{k}': missing (a torque data set needs t (N,), q (N, n), tau (N, n))")
    t = numeric_field(arrs["t"], path, "t", ndim=1)
    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    q = numeric_field(arrs["q"], path, "q", ndim=2)
    if q.shape[0] != t.size:
        raise DataError(f"{path}: field 'q': {q.shape[0]} rows but 't' has {t.size} samples")
    idx, extra, extra_names = joint_columns(arrs, path, joint_names, "q", q.shape[1])
    n = len(joint_names)
    rows = {"q": q[:, idx], "q_extra": q[:, extra]}
    tau = numeric_field(arrs["tau"], path, "tau", ndim=2)
    if tau.shape[0] != t.size:
        raise DataError(f"{path}: field 'tau': {tau.shape[0]} rows but 't' has {t.size} samples")
    # with a 'joints' array, torque columns as wide as the angle columns follow it like them
    # (permuted or with extra joints); otherwise they are in model joint order
    permuted = tau.shape[1] == q.shape[1] and ("joints" in arrs or q.shape[1] != n)
    if permuted:
        tau = tau[:, idx]
    if tau.shape[1] != n:
        raise DataError(f"{path}: field 'tau': expected {n} columns (model joints {list(joint_names)}), got {tau.shape[1]}")
    rows["tau"] = tau
    for k in ("qd", "qdd"):
        if k in arrs:
            a = numeric_field(arrs[k], path, k, ndim=2)
            if a.shape != q.shape:
                raise DataError(f"{path}: field '{k}': expected shape {q.shape} (as q), got {a.shape}")
            rows[k] = a[:, idx]
    reps = None
    if "tau_repeats" in arrs:
        r = numeric_field(arrs["tau_repeats"], path, "tau_repeats", ndim=3)
        if r.shape[1:] != (t.size, arrs["tau"].shape[1]):
            raise DataError(f"{path}: field 'tau_repeats': expected (R, {t.size}, {arrs['tau'].shape[1]}) (repeats of "
                            f"tau), got {r.shape}")
        reps = r[:, :, idx] if permuted else r
    if reps is not None and np.any(np.diff(t) <= 0):
        raise DataError(f"{path}: field 't': time must be strictly increasing (a set with tau_repeats is not resampled)")
    if reps is not None:
        rows["tau_repeats"] = np.moveaxis(reps, 0, 1)  # rows first, so conditioning keeps them aligned
    if not split:
        out, report, excluded = _conditioned(t, rows, path, joint_names, options)
        return out, extra_names, report, excluded
    cut = split_at_gaps(t, rows, str(path))
    if cut is None:
        return [(None, _conditioned(t, rows, path, joint_names, options))], None, extra_names
    stretches, split_report = cut
    out = []
    for a, b in stretches:
        m = (t >= a) & (t <= b)
        part = {k: v[m] for k, v in rows.items()}
        if m.sum() < MIN_WINDOW_SAMPLES:
            out.append(((a, b, int(m.sum())), None))
            continue
        out.append(((a, b, int(m.sum())), _conditioned(t[m], part, path, joint_names, options,
                                                        split_report["gap_bridge_limit_s"])))
    return out, split_report, extra_names


def _conditioned(t, rows, path, joint_names, options, bridge_s=None):
    """:func:`jflex.data.condition_torque` on the rows of one record (or of one stretch of it, with
    the longest gap bridged in the whole record ``bridge_s``), derivatives filled in.
    **Returns** ``(arrays, report, excluded joints)``."""
    t, out, report, excluded = condition_torque(
        t, rows, list(joint_names), str(path), keep=tuple(options.get("keep_channels") or ()),
        replace_spikes=bool(options.get("replace_spikes", False)), bridge_s=bridge_s)
    if "tau_repeats" in out:
        out["tau_repeats"] = np.moveaxis(out["tau_repeats"], 1, 0)
    out["t"] = t
    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    # derivatives missing: central differences of q (documented; the diagnosis filters an
    # angle-only or velocity-only set before differentiating, see jflex.data._angle_log)
    if "qd" not in out:
        out["qd"] = np.gradient(out["q"], t, axis=0)
    if "qdd" not in out:
        out["qdd"] = np.gradient(out["qd"], t, axis=0)
    return out, report, excluded
