"""A gap-diagnosis case: a nominal model plus measured data sets, validated before any fit.

A case is a folder with ``case.yaml`` (format in ``docs/case_format.md``). Every mistake a user
can make in it raises :class:`jflex.ConfigError` (the YAML) or :class:`jflex.DataError` (an NPZ
file) naming the file and the field, before anything is fitted.
"""

from __future__ import annotations

import dataclasses
import pathlib
import re
import warnings

import numpy as np

from ..._config import load_robot
from ..._errors import ConfigError, DataError, JFlexError
from ..._runs import load_yaml
from ..._schema import validate
from ...data._condition import BRIDGE, MAX_GAP, condition_torque, split_at_gaps
from ...data._npz import load_npz_fields
from ...data._posture import yaml_posture as yaml_posture
from ._schema import EFFECT_NAMES, EFFECT_VALUES, KINDS, SPLITS, CaseSpec, RobotSpec, file_format

__all__ = ["Case", "Dataset", "load_case", "case_path", "EFFECT_NAMES", "KINDS", "SPLITS"]


@dataclasses.dataclass
class Dataset:
    """One measured data set of a case, arrays in SI units.

    ``arrays`` holds the NPZ fields; for torque data ``q`` is reordered to the model's joints and
    ``q_extra`` / ``extra_joints`` keep the columns of joints the model leaves out. For FRF and
    modal data ``q0`` likewise becomes the model posture and ``q0_extra`` the rest.

    ``conditioning`` is what the data layer did to the samples (:mod:`jflex.data`: stamps made
    uniform, channels checked, spikes counted; for the report); ``excluded_channels`` the model
    joints whose torque channel it found dead, flat, stuck, saturated or few-level and that the
    case does not keep (``options.keep_channels``): the gap leaves them out. ``channels`` holds
    the per-channel metadata (:class:`jflex.data.Channel`), ``files`` every file read.

    A torque log with gaps too long to bridge gives one data set per stretch between them, named
    ``<name>#k`` (k counting the stretches in time order), each with the log's split, file and
    settings; ``conditioning["sampling"]["split_from"]`` says which stretch it is and lists the gaps.
    """

    kind: str
    file: pathlib.Path
    split: str
    name: str
    arrays: dict
    extra_joints: tuple[str, ...] = ()
    conditioning: dict = dataclasses.field(default_factory=dict)
    excluded_channels: tuple[str, ...] = ()
    channels: dict = dataclasses.field(default_factory=dict)
    files: tuple = ()


@dataclasses.dataclass
class Case:
    """A validated case: nominal robot, tool frame, nominal effects and data sets."""

    path: pathlib.Path
    robot: object
    tool_frame: str | None
    nominal_effects: list
    datasets: list
    noise: dict
    options: dict
    warnings: list = dataclasses.field(default_factory=list)

    def split(self, split: str, kind: str | None = None) -> list[Dataset]:
        """The data sets of ``split`` (``train``/``validation``), of ``kind`` if given."""
        return [d for d in self.datasets if d.split == split and (kind is None or d.kind == kind)]

    @property
    def excluded_channels(self) -> tuple[str, ...]:
        """Model joints whose torque channel some data set left out, in model order."""
        bad = {j for d in self.datasets for j in d.excluded_channels}
        return tuple(j for j in self.robot.joint_names if j in bad)


def _err(file, field, msg):
    return ConfigError(f"{file}: field '{field}': {msg}")


def _resolve_joints(spec, robot, file, field) -> tuple[str, ...]:
    names = tuple(robot.joint_names)
    if spec is None or spec == "all":
        return names
    items = [spec] if isinstance(spec, (str, int)) else list(spec)
    if "all" in items:
        raise _err(file, field, "'all' stands alone, not in a list")
    out = []
    for j in items:
        if isinstance(j, int) and not isinstance(j, bool):
            if not 0 <= j < len(names):
                raise _err(file, field, f"joint index {j} out of range; the model has joints {list(names)}")
            out.append(names[j])
        elif isinstance(j, str) and j in names:
            out.append(j)
        else:
            raise _err(file, field, f"unknown joint {j!r}; the model has joints {list(names)} (or 'all')")
    return tuple(out)


# the fields each kind of NPZ data set may hold (docs/case_format.md): only these are read
NPZ_KEYS = {"torque": ("t", "q", "tau", "qd", "qdd", "tau_repeats", "joints"),
            "frf": ("q0", "freq", "H", "H_repeats", "joints"),
            "modal": ("q0", "freq", "zeta", "shapes", "joints"),
            "response": ("t", "tau", "y", "channels", "q0", "y_repeats")}


def _num(arr, path, field, *, ndim=None, complex_ok=False, allow_nan=False):
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


def _columns(arrs, path, robot, width_field: str, width: int):
    """Map data columns to model joints with the optional ``joints`` name array."""
    names = tuple(robot.joint_names)
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


def _torque(arrs, path, robot, options=None, *, split: bool = False):
    """The torque data set's arrays in model joint order, conditioned (:func:`jflex.data.condition_torque`:
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
    t = _num(arrs["t"], path, "t", ndim=1)
    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    q = _num(arrs["q"], path, "q", ndim=2)
    if q.shape[0] != t.size:
        raise DataError(f"{path}: field 'q': {q.shape[0]} rows but 't' has {t.size} samples")
    idx, extra, extra_names = _columns(arrs, path, robot, "q", q.shape[1])
    n = robot.nq
    rows = {"q": q[:, idx], "q_extra": q[:, extra]}
    tau = _num(arrs["tau"], path, "tau", ndim=2)
    if tau.shape[0] != t.size:
        raise DataError(f"{path}: field 'tau': {tau.shape[0]} rows but 't' has {t.size} samples")
    # with a 'joints' array, torque columns as wide as the angle columns follow it like them
    # (permuted or with extra joints); otherwise they are in model joint order
    permuted = tau.shape[1] == q.shape[1] and ("joints" in arrs or q.shape[1] != n)
    if permuted:
        tau = tau[:, idx]
    if tau.shape[1] != n:
        raise DataError(f"{path}: field 'tau': expected {n} columns (model joints {list(robot.joint_names)}), got {tau.shape[1]}")
    rows["tau"] = tau
    for k in ("qd", "qdd"):
        if k in arrs:
            a = _num(arrs[k], path, k, ndim=2)
            if a.shape != q.shape:
                raise DataError(f"{path}: field '{k}': expected shape {q.shape} (as q), got {a.shape}")
            rows[k] = a[:, idx]
    reps = None
    if "tau_repeats" in arrs:
        r = _num(arrs["tau_repeats"], path, "tau_repeats", ndim=3)
        if r.shape[1:] != (t.size, arrs["tau"].shape[1]):
            raise DataError(f"{path}: field 'tau_repeats': expected (R, {t.size}, {arrs['tau'].shape[1]}) (repeats of "
                            f"tau), got {r.shape}")
        reps = r[:, :, idx] if permuted else r
    if reps is not None and np.any(np.diff(t) <= 0):
        raise DataError(f"{path}: field 't': time must be strictly increasing (a set with tau_repeats is not resampled)")
    if reps is not None:
        rows["tau_repeats"] = np.moveaxis(reps, 0, 1)  # rows first, so conditioning keeps them aligned
    if not split:
        out, report, excluded = _conditioned(t, rows, path, robot, options)
        return out, extra_names, report, excluded
    cut = split_at_gaps(t, rows, str(path))
    if cut is None:
        return [(None, _conditioned(t, rows, path, robot, options))], None, extra_names
    stretches, split_report = cut
    out = []
    for a, b in stretches:
        m = (t >= a) & (t <= b)
        part = {k: v[m] for k, v in rows.items()}
        if m.sum() < MIN_WINDOW_SAMPLES:
            out.append(((a, b, int(m.sum())), None))
            continue
        out.append(((a, b, int(m.sum())), _conditioned(t[m], part, path, robot, options,
                                                        split_report["gap_bridge_limit_s"])))
    return out, split_report, extra_names


def _conditioned(t, rows, path, robot, options, bridge_s=None):
    """:func:`jflex.data.condition_torque` on the rows of one record (or of one stretch of it, with
    the longest gap bridged in the whole record ``bridge_s``), derivatives filled in.
    **Returns** ``(arrays, report, excluded joints)``."""
    t, out, report, excluded = condition_torque(
        t, rows, list(robot.joint_names), str(path), keep=tuple(options.get("keep_channels") or ()),
        replace_spikes=bool(options.get("replace_spikes", False)), bridge_s=bridge_s)
    if "tau_repeats" in out:
        out["tau_repeats"] = np.moveaxis(out["tau_repeats"], 1, 0)
    out["t"] = t
    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    # derivatives missing: central differences of q (documented; the diagnosis filters an
    # angle-only or velocity-only set before differentiating, see jflex.gap.torque_set)
    if "qd" not in out:
        out["qd"] = np.gradient(out["q"], t, axis=0)
    if "qdd" not in out:
        out["qdd"] = np.gradient(out["qd"], t, axis=0)
    return out, report, excluded


STRETCH_MARK = "#"  # a stretch of a split log is named <data set>#<k>, k counting its stretches in time order


def _too_short(data, report, options) -> str | None:
    """Why a stretch cut from a log is too short for the diagnosis' processing of it
    (:func:`jflex.gap.torque_set`, with the case's ``filter_cutoff_hz`` and ``decimate``), or None:
    angles low-passed there lose ``EDGE_PERIODS`` periods of the cutoff at each end to the filter's
    transients and keep at least 20 samples per decimation step between them."""
    from ...data._condition import choose_cutoff
    from ..torque._set import CUTOFF_FACTOR, CUTOFF_LIMIT, EDGE_PERIODS

    t = data["t"]
    if report.get("derivatives") == "given":  # used as they are, unfiltered
        return None
    k = int(options.get("decimate") or 1)
    h = float(np.mean(np.diff(t)))
    fc = options.get("filter_cutoff_hz")
    if fc in (None, "auto"):
        qd = data["qd"] if report.get("derivatives") == "velocity" else None
        fc, _ = choose_cutoff(data["q"], h, qd=qd, factor=CUTOFF_FACTOR, decimate=k, limit=CUTOFF_LIMIT)
    edge = int(np.ceil(EDGE_PERIODS / fc / h))
    if t.size - 2 * edge >= 20 * k:
        return None
    return (f"its low-pass at {fc:.3g} Hz loses {edge * h:.3g} s at each end to its transients, leaving "
            f"{max(t.size - 2 * edge, 0)} of the {20 * k} samples needed")


def _stretches(stretches, split_report, base: str, path, options):
    """The data sets of one torque log (:func:`_torque` with ``split``): ``(kept, notes)``, ``kept``
    a list of ``(name, (arrays, report, excluded), split_from)``. A log conditioned whole keeps its
    name and ``split_from`` None. A log cut at gaps too long to bridge gives one data set per
    stretch, ``base#k`` (k counting every stretch in time order), each with ``split_from`` (the
    record, the stretch, its span and every gap of the log); a stretch too short to be processed
    is dropped. ``notes``: the sentences saying so, for the user and the report."""
    if split_report is None:
        (_, result), = stretches
        return [(base, result, None)], []
    gaps = split_report["gaps"]
    cut = [g for g in gaps if g["action"] == "split"]
    total = len(stretches)
    kept, dropped = [], []
    for k, ((a, b, rows), result) in enumerate(stretches, start=1):
        name = f"{base}{STRETCH_MARK}{k}"
        why = (f"{rows} sample(s), fewer than {MIN_WINDOW_SAMPLES}" if result is None
               else _too_short(*result[:2], options))
        if why is not None:
            dropped.append(f"'{name}' ({a:.6g} to {b:.6g} s, {rows} samples: {why})")
            continue
        split_from = {"record": base, "stretch": k, "stretches": total, "span_s": [a, b], "samples_in": rows,
                      "gaps": gaps, "gap_bridge_limit_s": split_report["gap_bridge_limit_s"]}
        kept.append((name, result, split_from))
    limit, band = split_report["gap_bridge_limit_s"], split_report.get("motion_band_hz")
    rule = (f"longer than {limit:.3g} s, {100 * BRIDGE:g} % of the shortest period of its motion (band {band:.3g} "
            "Hz), so interpolation would invent the motion in them") if band else \
        f"with no stretch of 256 samples to read the motion's band from, every gap over {MAX_GAP:g} median steps"
    named = "; ".join(f"{g['length_s']:.6g} s after t = {g['t_s']:.6g} s" for g in cut)
    bridged = len(gaps) - len(cut)
    if not kept:
        raise DataError(f"{path}: field 't': {len(cut)} gap(s) too long to bridge ({rule}: {named}) cut the log into "
                        f"{total} stretches, none long enough to be processed: {'; '.join(dropped)}; expected a "
                        "stretch between gaps longer than the low-pass' transients (or a log without such gaps)")
    notes = [f"'{base}' ({pathlib.Path(path).name}) is split at {len(cut)} gap(s) too long to bridge ({rule}): "
             f"{named}; its data sets are " + ", ".join(f"'{n}' ({s['span_s'][0]:.6g} to {s['span_s'][1]:.6g} s)"
                                                       for n, _, s in kept)
             + (f"; {bridged} shorter gap(s) bridged by interpolation" if bridged else "")]
    if dropped:
        notes.append(f"'{base}': stretch(es) between gaps too short to be processed, dropped: {'; '.join(dropped)}")
    return kept, notes


def _posture(arrs, path, robot):
    if "q0" not in arrs:
        raise DataError(f"{path}: field 'q0': missing (the posture (n,) [rad] of the measurement)")
    q0 = _num(arrs["q0"], path, "q0", ndim=1)
    idx, extra, names = _columns(arrs, path, robot, "q0", q0.size)
    return q0[idx], q0[extra], names


def _frf(arrs, path, robot):
    q0, q0x, names = _posture(arrs, path, robot)
    for k in ("freq", "H"):
        if k not in arrs:
            raise DataError(f"{path}: field '{k}': missing (an frf data set needs q0, freq (F,) [Hz], H (F, 3, 3))")
    f = _num(arrs["freq"], path, "freq", ndim=1)
    if f.size == 0:
        raise DataError(f"{path}: field 'freq': empty; expected at least one frequency line")
    if np.any(f <= 0) or np.any(np.diff(f) <= 0):
        raise DataError(f"{path}: field 'freq': frequencies must be > 0 Hz and strictly increasing")
    H = _num(arrs["H"], path, "H", ndim=3, complex_ok=True)
    if H.shape != (f.size, 3, 3):
        raise DataError(f"{path}: field 'H': expected shape ({f.size}, 3, 3) (freq x output x input), got {H.shape}")
    out = {"q0": q0, "q0_extra": q0x, "freq": f, "H": H.astype(complex)}
    if "H_repeats" in arrs:
        r = _num(arrs["H_repeats"], path, "H_repeats", ndim=4, complex_ok=True).astype(complex)
        if r.shape[1:] != H.shape or r.shape[0] < 2:
            raise DataError(f"{path}: field 'H_repeats': expected shape (R, {f.size}, 3, 3) with R >= 2 repeats of H, "
                            f"got {r.shape}")
        out["H_repeats"] = r
    return out, names


def _modal(arrs, path, robot):
    q0, q0x, names = _posture(arrs, path, robot)
    for k in ("freq", "zeta"):
        if k not in arrs:
            raise DataError(f"{path}: field '{k}': missing (a modal data set needs q0, freq (M,) [Hz], zeta (M,))")
    f = _num(arrs["freq"], path, "freq", ndim=1)
    if f.size == 0:
        raise DataError(f"{path}: field 'freq': the modal table is empty; expected at least one mode")
    z = _num(arrs["zeta"], path, "zeta", ndim=1, allow_nan=True)
    if np.any(f <= 0):
        raise DataError(f"{path}: field 'freq': natural frequencies must be > 0 Hz")
    if z.shape != f.shape:
        raise DataError(f"{path}: field 'zeta': expected shape {f.shape} (one ratio per mode), got {z.shape}")
    if np.any(z[~np.isnan(z)] < 0) or np.any(z[~np.isnan(z)] >= 1):  # NaN: not measured; +-inf is refused
        raise DataError(f"{path}: field 'zeta': damping ratios must lie in [0, 1) (a ratio, not a percentage)")
    out = {"q0": q0, "q0_extra": q0x, "freq": f, "zeta": z}
    if "shapes" in arrs:
        s = _num(arrs["shapes"], path, "shapes", ndim=2, complex_ok=True)
        if s.shape[1] != f.size:
            raise DataError(f"{path}: field 'shapes': expected (s, {f.size}) (one column per mode), got {s.shape}")
        out["shapes"] = s
    return out, names


TIP_CHANNELS = ("tip_x", "tip_y", "tip_z")  # [m] origin of the case's tool_frame in base axes
RESPONSE_NOISE_DRAWS = 4  # noise realisations propagated into the equation error (noise floor)
RESPONSE_CUTOFF_FACTOR = 2.0
RESPONSE_SG_ORDER = 5
RESPONSE_SNR = 100.0  # the motion's band ends where its spectrum falls to 100 x the angle-noise level


def _response(arrs, path, robot):
    for k in ("t", "tau", "y", "channels"):
        if k not in arrs:
            raise DataError(f"{path}: field '{k}': missing (a response data set needs t, tau (N, n), y (N, k), channels (k,))")
    t = _num(arrs["t"], path, "t", ndim=1)
    tau = _num(arrs["tau"], path, "tau", ndim=2)
    y = _num(arrs["y"], path, "y", ndim=2)
    ch = tuple(str(c) for c in np.asarray(arrs["channels"]).ravel())
    if tau.shape[0] != t.size or y.shape[0] != t.size:
        raise DataError(f"{path}: fields 'tau'/'y': expected {t.size} rows (as t), got {tau.shape[0]} and {y.shape[0]}")
    if len(ch) != y.shape[1]:
        raise DataError(f"{path}: field 'channels': {len(ch)} names for {y.shape[1]} columns of 'y'")
    if len(set(ch)) != len(ch):
        raise DataError(f"{path}: field 'channels': names must be unique, got {list(ch)}")
    n = robot.nq
    if tau.shape[1] != n:
        raise DataError(f"{path}: field 'tau': expected {n} columns (applied torques at the model joints "
                        f"{list(robot.joint_names)}), got {tau.shape[1]}")
    known = tuple(robot.joint_names) + TIP_CHANNELS
    bad = [c for c in ch if c not in known]
    if bad:
        raise DataError(f"{path}: field 'channels': unknown channels {bad}; a channel is a model joint "
                        f"{list(robot.joint_names)} [rad] or one of {list(TIP_CHANNELS)} [m] (the case's tool_frame)")
    out = {"t": t, "tau": tau, "y": y, "channels": ch}
    if all(j in ch for j in robot.joint_names):
        out.update(_response_motion(t, tau, y, ch, path, robot))
        return out, ()
    # output error: the model is simulated under tau from rest at q0 and its channels compared
    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    if np.any(np.diff(t) <= 0):
        raise DataError(f"{path}: field 't': time must be strictly increasing")
    if "q0" not in arrs:
        raise DataError(f"{path}: field 'q0': missing (a response whose channels do not name every model joint "
                        f"{list(robot.joint_names)} is simulated from rest at q0 ({n},) [rad])")
    q0 = _num(arrs["q0"], path, "q0")
    if q0.shape != (n,):
        raise DataError(f"{path}: field 'q0': expected shape ({n},) (the rest posture at t[0], model joints "
                        f"{list(robot.joint_names)} in that order) [rad], got shape {q0.shape}")
    out["q0"] = q0
    if "y_repeats" in arrs:
        r = _num(arrs["y_repeats"], path, "y_repeats", ndim=3)
        if r.shape[1:] != y.shape:
            raise DataError(f"{path}: field 'y_repeats': expected (R, {y.shape[0]}, {y.shape[1]}) (repeats of y), got {r.shape}")
        out["y_repeats"] = r
    return out, ()


def _uniform_response(arrs, path):
    """A response set's rows resampled onto a uniform grid when its stamps jitter or drop samples
    (:func:`jflex.data.resample_uniform`); ``(arrays, sampling report or None)``. Malformed
    fields are left to :func:`_response` to name."""
    from ...data._condition import resample_uniform

    try:
        t = np.asarray(arrs["t"], float)
        tau, y = np.asarray(arrs["tau"], float), np.asarray(arrs["y"], float)
    except (KeyError, TypeError, ValueError):
        return arrs, None
    if t.ndim != 1 or t.size < 20 or tau.shape[:1] != t.shape or y.shape[:1] != t.shape or \
            not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        return arrs, None
    rows = {"tau": tau, "y": y}
    if "y_repeats" in arrs and np.ndim(arrs["y_repeats"]) == 3 and np.shape(arrs["y_repeats"])[1] == t.size:
        rows["y_repeats"] = np.moveaxis(np.asarray(arrs["y_repeats"], float), 0, 1)
    t2, rows, report = resample_uniform(t, rows, str(path))
    if not report["resampled"]:
        return arrs, report
    out = {**arrs, "t": t2, "tau": rows["tau"], "y": rows["y"]}
    if "y_repeats" in rows:
        out["y_repeats"] = np.moveaxis(rows["y_repeats"], 1, 0)
    return out, report


def _motion_band(q_raw, sig, fs):
    """Highest frequency [Hz] where some joint's angle spectrum (Welch) stands ``RESPONSE_SNR``
    above the white angle noise ``sig`` [rad].

    Not :func:`jflex.identify.motion_band`, on purpose: that one (the band off the second
    difference, held within 2 x the 99.9 % power band on quantised angles) serves the Butterworth
    filter of torque logs. Here it gave bands of about 1 Hz where this one gives 1.4-5 Hz on the
    response tests' trajectories (harmonics up to 0.5 Hz), so a Savitzky-Golay window 1.4-5 x as
    long; with it the gap a planted rotor inertia leaves once fitted was 1.9 x the propagated floor
    (0.72 against 0.38 %) and a null case with 1 mrad angle noise read as significant (the
    smoothing's own error on the motion, it seems, which a floor propagated from noise lacks)."""
    from scipy.signal import welch

    nper = min(len(q_raw), 1024)
    f, P = welch(q_raw - q_raw.mean(axis=0), fs=fs, nperseg=nper, axis=0)
    level = 2.0 * np.maximum(sig, 1e-15) ** 2 / fs  # one-sided PSD of white noise of std sig
    above = (P > RESPONSE_SNR * level[None, :]).any(axis=1)
    return float(f[np.flatnonzero(above)[-1]]) if above.any() else float(f[1])


def _response_motion(t, tau, y, ch, path, robot):
    """Joint channels of a response as an equation-error data set: measured angles smoothed and
    differentiated (Savitzky-Golay, cubic), the applied torques as ``tau``. The window puts the
    filter's cutoff at twice the band of the motion, the band read off the angles' spectrum
    against their noise (:func:`_motion_band`).

    The differentiation turns angle noise into coloured torque-residual noise, which the
    residual's own high-frequency content would understate; so the noise of the angles (robust
    spread of their second difference) is propagated instead: ``tau_repeats`` holds the applied
    torques plus the nominal model's torque change under ``RESPONSE_NOISE_DRAWS`` redraws of it.
    """
    from scipy.signal import savgol_filter

    from ..torque._set import _id_batch, on_rows

    if t.size < 20:
        raise DataError(f"{path}: field 't': need at least 20 samples, got {t.size}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise DataError(f"{path}: field 't': time must be strictly increasing")
    if np.max(np.abs(dt - dt.mean())) > 0.01 * dt.mean():
        raise DataError(f"{path}: field 't': joint-angle channels need uniform sampling (steps vary by "
                        f"{100 * np.max(np.abs(dt - dt.mean())) / dt.mean():.1f} %, more than 1 %)")
    h = float(dt.mean())
    q_raw = y[:, [ch.index(j) for j in robot.joint_names]]
    d2 = q_raw[2:] - 2 * q_raw[1:-1] + q_raw[:-2]
    sig = 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) / np.sqrt(6)
    fc = RESPONSE_CUTOFF_FACTOR * _motion_band(q_raw, sig, 1.0 / h)
    # Savitzky-Golay of order p and half-width m has its -3 dB point near (p + 1) / (3.2 m - 4.6)
    # x Nyquist (Schafer 2011)
    p = RESPONSE_SG_ORDER
    m = int(np.clip(((p + 1) * (0.5 / h) / fc + 4.6) / 3.2, p, (t.size - 1) // 2))
    win = 2 * m + 1

    def derive(qr):
        return tuple(savgol_filter(qr, win, p, deriv=k, delta=h, axis=0) for k in range(3))

    q, qd, qdd = derive(q_raw)
    rng = np.random.default_rng(0)
    # the torque sets' compiled batch inverse dynamics: one compile per robot structure
    F0 = on_rows(_id_batch, (robot,), (q, qd, qdd))
    reps = []
    for _ in range(RESPONSE_NOISE_DRAWS):
        qk, qdk, qddk = derive(q + sig * rng.standard_normal(q.shape))
        reps.append(tau + on_rows(_id_batch, (robot,), (qk, qdk, qddk)) - F0)
    return {"q": q, "qd": qd, "qdd": qdd, "q_extra": np.zeros((t.size, 0)), "tau_repeats": np.stack(reps),
            "angle_noise_rad": sig, "cutoff_hz": fc, "window_samples": win}


_LOADERS = {"torque": _torque, "frf": _frf, "modal": _modal, "response": _response}
_CONFIG_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


def case_path(base: pathlib.Path, rel: str, field: str, case_file, allow_outside: bool = False) -> pathlib.Path:
    """``rel`` (a path case.yaml gives in ``field``) resolved against the case folder ``base``.

    Unless ``allow_outside``, an absolute path and one that leaves the folder (``..``, or a
    symbolic link pointing out, resolved first) raise :class:`ConfigError` naming the field; the
    file is not opened.
    """
    if "\x00" in rel:
        raise _err(case_file, field, f"{rel[:80]!r} contains a NUL byte; expected a file path")
    p = pathlib.Path(rel)
    if allow_outside:
        return base / p
    hint = "case files lie inside the case folder (pass allow_outside=True, or --allow-outside to jflex diagnose, to read it)"
    if p.is_absolute() or p.drive:
        raise _err(case_file, field, f"absolute path {rel!r}: {hint}")
    root = base.resolve()
    if not (base / p).resolve().is_relative_to(root):
        raise _err(case_file, field, f"{rel!r} resolves outside the case folder: {hint}")
    return base / p


def _load_robot(spec: str, base, file, allow_outside):
    within = None  # a robot YAML in the case names its URDF inside the case folder too (unless allowed out)
    if pathlib.PurePath(spec).suffix.lower() in (".urdf", ".yaml", ".yml"):
        rp = case_path(base, spec, "robot", file, allow_outside)
        target = str(rp)
        within = None if allow_outside else base
    elif _CONFIG_NAME.match(spec):
        target = spec
    else:
        raise _err(file, "robot", f"expected a .urdf/.yaml file or a config name such as panda, got {spec!r}")
    try:
        return load_robot(target, within=within)
    except JFlexError as exc:
        raise ConfigError(f"{file}: field 'robot': {exc}") from None


def _refuse_mimic(robot, file):
    """A robot with coupled (<mimic>) joints is refused by name: every effect of the diagnosis (the
    nominal friction, each candidate) indexes joints as coordinates, which a follower has none of
    (jflex.Model refuses effects on it), and its data would need a column per coordinate."""
    mimic = getattr(robot, "mimic", ())
    pairs = [(robot.joint_names[i], robot.joint_names[k]) for i, k in enumerate(mimic) if k >= 0]
    if pairs:
        raise _err(file, "robot", "joints coupled by <mimic> are not supported by the diagnosis ("
                   + ", ".join(f"{f} follows {lead}" for f, lead in pairs) + "); expected a robot without them: "
                   "lock the leaders, which locks their followers (robot: {file: ..., lock: {"
                   + ", ".join(f"{lead}: 0.0" for lead in dict.fromkeys(lead for _, lead in pairs))
                   + "}}), or keep only the other joints (robot: {file: ..., joints: [...]})")


def _load_reduced_robot(rs, base, file, allow_outside):
    """The robot of a ``robot: {file, joints, lock}`` entry: a URDF (or a robot YAML / config name
    resolving to one) reduced to ``joints``, the others locked (:func:`jflex.load_urdf`)."""
    from ..._config import _example_robot_urdf, robot_from_config
    from ..._urdf import load_urdf

    spec = rs.file
    suffix = pathlib.PurePath(spec).suffix.lower()
    red = {k: v for k, v in (("joints", rs.joints), ("lock", rs.lock)) if v is not None}
    try:
        if suffix == ".urdf":
            return load_urdf(case_path(base, spec, "robot.file", file, allow_outside), **red)
        if suffix in (".yaml", ".yml"):
            rp = case_path(base, spec, "robot.file", file, allow_outside)
            cfg = load_yaml(rp)
            if not isinstance(cfg, dict) or "urdf" not in cfg:
                raise _err(file, "robot.joints", f"{rp.name} is not a robot YAML naming a URDF (urdf:); only a URDF "
                           "robot is reduced")
            cfg = {**cfg, **red}
            return robot_from_config(cfg, where=str(rp), base=rp.parent, within=None if allow_outside else base)
        if not _CONFIG_NAME.match(spec):
            raise _err(file, "robot.file", f"expected a .urdf/.yaml file or a config name such as panda, got {spec!r}")
        urdf = _example_robot_urdf(spec)
        if urdf is None:
            raise _err(file, "robot.file", f"{spec!r} is not a robot whose URDF can be reduced (joints/lock need a "
                       "URDF: name the .urdf file)")
        return load_urdf(urdf, **red)
    except ConfigError:
        raise
    except JFlexError as exc:
        raise ConfigError(f"{file}: field 'robot': {exc}") from None


def _nominal(specs, robot, file) -> list[dict]:
    nominal, seen = [], {}
    for i, e in enumerate(specs):
        fld = f"nominal_effects[{i}]"
        joints = _resolve_joints(e.joint, robot, file, fld + ".joint")
        for j in joints:
            if (e.effect, j) in seen:
                raise _err(file, fld + ".joint", f"effect {e.effect!r} at joint {j!r} is already given by "
                           f"{seen[(e.effect, j)]}; give each effect once per joint")
            seen[(e.effect, j)] = fld
        d = {"effect": e.effect, "joints": joints}
        for k in EFFECT_VALUES.get(e.effect, ()):
            v = getattr(e, k)
            if v is None:
                continue
            if len(v) not in (1, len(joints)):
                raise _err(file, f"{fld}.{k}", f"expected a number or {len(joints)} numbers (one per joint "
                           f"{list(joints)}), got {len(v)}")
            d[k] = np.broadcast_to(np.asarray(v, dtype=float), (len(joints),)).copy()
        nominal.append(d)
    return nominal


MIN_WINDOW_SAMPLES = 20  # a torque record shorter than this is refused (see _torque)


def window_mask(t, window) -> np.ndarray:
    """The samples of the stamps ``t`` inside ``window`` = [start, end] seconds from the first
    stamp (``end`` None: to the end); ``jflex case init --hold-out`` checks its split with it."""
    t = np.asarray(t, float)
    start, end = window
    rel = t - t[0]
    return (rel >= start) & (rel <= (np.inf if end is None else end))


def _window(arrs: dict, window, path, fld: str, case_file) -> dict:
    """The samples of a time record (``t`` and every array with a time axis: the first one, the
    second one of ``*_repeats``) inside ``window`` = [start, end] seconds from its first stamp."""
    t = np.asarray(arrs["t"], float)
    rel = t - t[0]
    keep = window_mask(t, window)
    if keep.sum() < MIN_WINDOW_SAMPLES:
        raise _err(case_file, f"{fld}.window", f"{list(window)} s keeps {int(keep.sum())} samples of {path.name} "
                   f"(its record lasts {rel[-1]:.4g} s): expected a window inside the record with at least 20")
    out = {}
    for k, v in arrs.items():
        a = np.asarray(v)
        if k.endswith("_repeats") and a.ndim >= 2 and a.shape[1] == t.size:
            out[k] = a[:, keep]
        elif a.ndim >= 1 and a.shape[0] == t.size:
            out[k] = a[keep]
        else:
            out[k] = v
    return out


def load_case(path, *, allow_outside: bool = False) -> Case:
    """Read and validate a case folder (or its ``case.yaml``).

    **Arguments:**

    - ``path``: the folder holding ``case.yaml``, or the YAML file itself.
    - ``allow_outside``: let ``robot``, ``robot_inertia`` and data ``file`` paths leave the case
      folder (absolute paths, ``..``); off by default, so a case reads only its own files.

    **Returns:** a :class:`Case`. Raises :class:`jflex.ConfigError` / :class:`jflex.DataError`
    naming the file and field of the first problem found. A torque log with gaps too long to
    bridge is split at them into several data sets (see :class:`Dataset`), a stretch too short
    for the low-pass dropped; both are warned of (a ``UserWarning``, kept in ``Case.warnings`` and
    the first stretch's ``conditioning["warnings"]``). The schema of ``case.yaml`` is
    :class:`jflex.gap.case._schema.CaseSpec` (the table in ``docs/case_format.md``).
    """
    from ...data._csv import read_csv
    from ...data._npz import read_npz
    from ...data._record import Record
    from ...data._rosbag import read_rosbag
    from ...data._uff import uff_arrays

    p = pathlib.Path(path)
    file = p / "case.yaml" if p.is_dir() else p
    if not file.is_file():
        raise ConfigError(f"{file}: case file not found (a case is a folder with case.yaml)")
    base = file.parent
    spec = validate(CaseSpec, load_yaml(file), file, context={"folder": base})
    # the robot's warnings (a massless link, a non-physical inertia) are the user's to see, and the
    # report's: passed on, and kept
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if isinstance(spec.robot, RobotSpec):
            robot = _load_reduced_robot(spec.robot, base, file, allow_outside)
        else:
            robot = _load_robot(spec.robot, base, file, allow_outside)
    notes = []
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if issubclass(w.category, UserWarning):
            notes.append(str(w.message))
    _refuse_mimic(robot, file)
    unknown = [j for j in spec.options.keep_channels if j not in robot.joint_names]
    if unknown:
        raise _err(file, "options.keep_channels", f"unknown joints {unknown}; expected joint names of the model "
                   f"{list(robot.joint_names)}")
    if spec.robot_inertia is not None:
        # link parameters realised from identified base parameters need not be physically
        # consistent per link (only their combinations are identified): taken as they are
        ip = case_path(base, spec.robot_inertia, "robot_inertia", file, allow_outside)
        arr = load_npz_fields(ip, "robot_inertia", file, ("inertia",))
        if "inertia" not in arr:
            raise DataError(f"{ip}: field 'inertia': missing ((n, 10) link parameters in Pinocchio's order)")
        P = _num(arr["inertia"], ip, "inertia", ndim=2)
        if P.shape != (robot.nq, 10):
            raise DataError(f"{ip}: field 'inertia': expected shape ({robot.nq}, 10), got {P.shape}")
        robot = robot.replace(inertia=P)
    tool = spec.tool_frame
    if tool is not None:
        try:
            robot.frame_index(tool)
        except JFlexError:
            raise _err(file, "tool_frame", f"unknown frame {tool!r}; frames: {list(robot.link_names) + list(robot.frame_names)}") from None
    nominal = _nominal(spec.nominal_effects, robot, file)
    datasets, specs, split_notes = [], [], []
    for i, d in enumerate(spec.datasets):
        fld = f"datasets[{i}]"
        if d.kind == "frf" and tool is None:
            raise _err(file, "tool_frame", f"needed by the frf data set {fld} (FRFs are at the tool frame)")
        many = isinstance(d.file, list)
        fpaths = [case_path(base, f, f"{fld}.file" + (f"[{k}]" if many else ""), file, allow_outside)
                  for k, f in enumerate(d.file if many else [d.file])]
        fpath = fpaths[0]
        fmt = file_format(fpaths[0].name if many else d.file, base)
        if fmt == "csv":
            rec = read_csv(fpaths, d, robot, file, fld)
        elif fmt == "rosbag":
            rec = read_rosbag(fpath, d, robot, file, fld)
        elif fmt == "uff":
            rec = Record(uff_arrays(fpath, d, robot, file, fld))
        else:
            rec = read_npz(fpath, f"{fld}.file", file, NPZ_KEYS[d.kind])
        if d.window is not None:
            rec.arrays = _window(rec.arrays, d.window, fpath, fld, file)
            rec.conditioning["window_s"] = list(d.window)
        cond, excluded = dict(rec.conditioning), ()
        if d.kind == "torque":
            options = spec.options.model_dump()
            stretches, split_report, extra = _torque(rec.arrays, fpath, robot, options, split=True)
            kept, notes_split = _stretches(stretches, split_report, d.name or fpath.stem, fpath, options)
            for piece_name, (data, report, excluded), split_from in kept:
                pcond, channels = dict(cond), dict(rec.channels)
                if "sampling" in pcond:  # the reader resampled already: its numbers describe the raw stamps
                    report["sampling"] = {**report["sampling"], **pcond.pop("sampling")}
                if split_from is not None:
                    report["sampling"]["split_from"] = split_from
                pcond.update(report)
                piece = Record(rec.arrays, channels)
                for j, c in report["channels"].items():
                    if c["flags"]:
                        piece.flag(f"tau:{j}", *c["flags"])
                datasets.append(Dataset(d.kind, fpath, d.split, piece_name, data, extra, pcond, excluded,
                                        piece.channels, tuple(fpaths)))
                specs.append(d)
            for msg in notes_split:
                warnings.warn(msg, UserWarning, stacklevel=2)
                datasets[-len(kept)].conditioning.setdefault("warnings", []).append(msg)
            split_notes += notes_split
            continue
        else:
            arrs = rec.arrays
            if d.kind == "response":
                arrs, sampling = _uniform_response(arrs, fpath)
                if sampling is not None:
                    cond["sampling"] = {**sampling, **cond.get("sampling", {})}
            data, extra = _LOADERS[d.kind](arrs, fpath, robot)
        if d.kind == "response" and tool is None and any(c in TIP_CHANNELS for c in data["channels"]):
            raise _err(file, "tool_frame", f"needed by the response data set {fld} ({fpath.name}): its tip channels "
                       "are positions of the tool frame")
        datasets.append(Dataset(d.kind, fpath, d.split, d.name or fpath.stem, data, extra, cond, excluded,
                                rec.channels, tuple(fpaths)))
        specs.append(d)
    names = [d.name for d in datasets]
    if len(set(names)) != len(names):
        raise _err(file, "datasets", f"data set names must be unique, got {names}")
    if not any(d.split == "train" for d in datasets):
        raise _err(file, "datasets", "no data set has split: train (the nominal model is fitted on it)")
    if not any(d.split == "validation" for d in datasets):
        raise _err(file, "datasets", "no data set has split: validation (the gap is judged on held-out data)")
    _refuse_long_delay(nominal, datasets, file)
    sets_notes = _held_out_notes(specs, datasets) + _short_training_notes(spec, nominal, datasets, robot)
    for d, msg in sets_notes:
        warnings.warn(msg, UserWarning, stacklevel=2)
        d.conditioning.setdefault("warnings", []).append(msg)
    if notes:  # the robot's: with the first training set's, where the report's data notes show them
        first = next(d for d in datasets if d.split == "train")
        first.conditioning["warnings"] = notes + first.conditioning.get("warnings", [])
    # noise: only what the case states (the diagnosis reports a default as such); options: all,
    # defaults filled
    noise = spec.noise.model_dump(exclude_none=True)
    return Case(file, robot, tool, nominal, datasets, noise, spec.options.model_dump(),
                notes + split_notes + [m for _, m in sets_notes])


DELAY_SHARE = 0.1  # a nominal sensor delay is a small lag of the record, at most this share of it


def _duration(d) -> float | None:
    t = d.arrays.get("t") if d.kind in ("torque", "response") else None
    return None if t is None or np.size(t) < 2 else float(np.max(t) - np.min(t))


def _refuse_long_delay(nominal, datasets, file) -> None:
    """A nominal ``sensor_delay`` shifts every record by its value: one of a sizeable share of the
    shortest record leaves nothing to compare (and is a unit slip: ms written as s)."""
    spans = [(_duration(d), d.name) for d in datasets if _duration(d)]
    if not spans:
        return
    span, name = min(spans)
    for i, e in enumerate(nominal):
        if e["effect"] == "sensor_delay" and "value" in e and float(np.max(e["value"])) > DELAY_SHARE * span:
            raise _err(file, f"nominal_effects[{i}].value", f"a delay of {float(np.max(e['value'])):.4g} s against the "
                       f"record '{name}' of {span:.4g} s: expected a delay well below the record length (at most "
                       f"{DELAY_SHARE:g} x it, {DELAY_SHARE * span:.3g} s; a delay is given in seconds)")


def _span(window):
    a, b = (window or [0.0, None])
    return float(a), float("inf") if b is None else float(b)


def _held_out_notes(specs, datasets) -> list:
    """``(validation set, sentence)`` for each validation set that holds the same samples as a
    training set (the same file and overlapping windows, or the same torques): the gap is then
    judged on data the model was fitted on, and nothing is held out. ``specs``: the case.yaml
    entry of each data set (the stretches of a split log share theirs)."""
    out = []
    for v, vs in zip(datasets, specs):
        if v.split != "validation":
            continue
        for t, ts in zip(datasets, specs):
            if t.split != "train" or t.kind != v.kind:
                continue
            (a0, a1), (b0, b1) = _span(ts.window), _span(vs.window)
            overlap = min(a1, b1) - max(a0, b0)
            same_file = tuple(t.files) == tuple(v.files) and overlap > 0
            ta, va = t.arrays.get("tau"), v.arrays.get("tau")
            same_data = (ta is not None and va is not None and np.shape(ta) == np.shape(va)
                         and np.array_equal(ta, va))
            if same_file or same_data:
                how = (f"overlapping windows of {', '.join(p.name for p in v.files)}" if same_file and not same_data
                       else "the same samples")
                out.append((v, f"validation set '{v.name}' and training set '{t.name}' hold {how}: nothing is held "
                               "out, so the gap is judged on data the model was fitted on (an effect can look "
                               "explained that held-out data would not confirm); expected a validation set of "
                               "other samples (another log, or 'jflex case init --hold-out')"))
                break
    return out


# equations (training samples x torque channels) per fitted parameter below which the nominal
# identification is warned of: a least-squares fit of p parameters on r rows leaves r - p degrees
# of freedom for the residual (and the noise floor read off it)
ROWS_PER_PARAMETER = 10


def _short_training_notes(spec, nominal, datasets, robot) -> list:
    """``(training set, sentence)`` when the torque training data are too short to identify the
    nominal model: fewer than ``ROWS_PER_PARAMETER`` equations per parameter fitted (10 inertial
    parameters per link when they are refitted, one coefficient per nominal friction term and
    joint)."""
    train = [d for d in datasets if d.split == "train" and d.kind == "torque"]
    if not train:
        return []
    n = robot.nq
    params = (10 * n if spec.options.refit_inertia else 0) + sum(
        len(e["joints"]) for e in nominal if e["effect"] != "joint_flexibility" and "value" not in e)
    rows = sum(int(np.shape(d.arrays["tau"])[0]) * n for d in train)
    if params == 0 or rows >= ROWS_PER_PARAMETER * params:
        return []
    samples = sum(int(np.shape(d.arrays["tau"])[0]) for d in train)
    return [(train[0], f"the torque training data are too short to identify the nominal model: {samples} samples x "
                       f"{n} joints = {rows} equations for {params} parameters (expected at least "
                       f"{ROWS_PER_PARAMETER} equations per parameter, {-(-ROWS_PER_PARAMETER * params // n)} samples "
                       "here); the fit follows the noise and the verdict is weak")]
