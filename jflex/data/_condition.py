"""Conditioning of measured time series before any model sees them: time stamps made uniform,
files merged on time, broken channels named, spikes found, the low-pass cutoff chosen per record,
motor currents turned into joint torques. Every step says what it did in a report (a dict of
plain numbers and strings, written into the diagnosis as it is).
"""

from __future__ import annotations

import numpy as np

from .._errors import DataError
from ._signal import (POWER_RESOLUTION, angle_noise, held_by_power, motion_band, power_band, power_segment,
                      robust_sigma)

JITTER = 0.01  # largest deviation of a step from the median step kept as it is (relative)
DROP = 1.5  # a step over 1.5 median steps: samples were dropped there
MAX_GAP = 5.0  # longest step (in median steps) resampling always bridges
BRIDGE = 0.05  # ... and beyond, a gap shorter than this fraction of the motion's shortest period (1 / its band):
# linear interpolation over it misses at most (pi BRIDGE)^2 / 2, about 1 %, of the band edge's amplitude
STALE_RUN = 3  # rows equal to the previous one in every channel, in runs up to this long, are stale readings
# (removed and interpolated); a longer run is a robot at rest logged without noise, kept as it is
JUMP = 50.0  # an angle step over 50 x every step near it is a splice, not motion
JUMP_WINDOW = 5  # samples each side a step is compared with
JUMP_QUANTILE = 0.99  # the moving steps' quantile a splice also stands JUMP x above

DEAD_ZEROS = 0.5  # a channel reading exactly 0 in half of its samples or more is off
STUCK_RUN = 0.25  # ... holding one value for a quarter of the record in one run is stuck
FLAT_REL = 1e-4  # ... whose spread is below 1e-4 of the median spread of its fellows is flat
CLIP_RUN = 5  # ... sitting at its largest or smallest value for runs of 5 samples or more (and longer than
# twice any other value's hold) while the robot moves clips there: those samples are masked (``tau_valid``)
FEW_LEVELS = 8  # ... taking fewer distinct values than this carries no waveform
EXCLUDE_FLAGS = ("dead", "flat", "stuck", "few_levels")  # left out of the gap (a saturated one is masked)

SPIKE_WINDOW = 7  # samples of the running median a spike is measured against
SPIKE_SIGMA = 8.0  # a spike stands this many robust standard deviations off the running median
SPIKE_SCALE_WINDOW = 201  # samples of the local noise scale a spike is judged against

CUTOFF_FACTOR = 2.5  # the low-pass sits at 2.5 x the motion's band (the band's edge passes flat)
CUTOFF_LIMIT = 0.8  # x Nyquist: the highest cutoff a record may get (its filter must still cut)
FLOOR_SNR = 100.0  # fallback band: where the angle spectrum stands 100 x above its own high-frequency floor
ENERGY_FRACTION = 0.999  # last fallback band: the frequency below which this share of the angle power lies
TAIL_FRACTION = 1e-6  # spectrum_floor's band ends where each angle column has all but this share of its power


def _stale_rows(same_row) -> np.ndarray:
    """(N,) bool: the rows of ``same_row`` (equal to the previous row) in runs of at most ``STALE_RUN``."""
    run = np.concatenate([[0], np.cumsum(same_row[1:] != same_row[:-1])])
    length = np.bincount(run)[run]
    return same_row & (length <= STALE_RUN)


def clean_stamps(t, arrays: dict, where: str):
    """Repeated time stamps removed (the first row kept), stale rows removed, a step back in time
    refused.

    **Returns** ``(t, arrays, report)``; the report counts ``repeated_stamps`` (rows dropped) and
    ``repeated_rows`` (stale rows removed: rows equal to the previous one in every channel at a
    later stamp, a logger that wrote its last sample again, in runs of at most ``STALE_RUN``; kept,
    they hold the motion still for a step and put a kink into every derivative. The resampling
    interpolates across them. A longer run of equal rows is a robot at rest and stays). With stale
    rows, it also gives the logged stamps' ``longest_step`` and ``dropped_samples`` (as
    :func:`resample_uniform` reports them, before the stale rows are let go)."""
    t = np.asarray(t, float)
    dt = np.diff(t)
    if t.size > 1 and np.all(dt == 0):
        raise DataError(f"{where}: field 't': the stamps are all equal ({t.size} rows at {t[0]:.9g} s); a time "
                        "series needs increasing stamps (is the time column the right one?)")
    if np.any(dt < 0):
        k = int(np.argmax(dt < 0))
        raise DataError(f"{where}: field 't': time goes back at sample {k + 1} ({t[k + 1]:.9g} s after "
                        f"{t[k]:.9g} s); sort the log or cut it there")
    keep = np.concatenate([[True], dt > 0])
    stacked = np.column_stack([np.asarray(a, float).reshape(t.size, -1) for a in arrays.values()]) if arrays \
        else np.zeros((t.size, 0))
    if stacked.shape[1]:
        # equal to the previous row at a new stamp (rows at a repeated stamp are dropped first)
        k = np.flatnonzero(keep)
        same = np.concatenate([[False], np.all(stacked[k[1:]] == stacked[k[:-1]], axis=1)])
        stale = np.zeros(t.size, bool)
        stale[k] = _stale_rows(same)
    else:
        stale = np.zeros(t.size, bool)
    report = {"repeated_stamps": int((~keep).sum()), "repeated_rows": int(stale.sum())}
    if stale.any():
        # the clock's own longest step and drops (as resample_uniform reports them), before the stale
        # rows' stamps are let go: those were logged, only their values were old
        d = np.diff(t[keep])
        h = float(np.median(d))
        report.update(longest_step=float(d.max() / h), dropped_samples=int(np.sum(np.round(d[d > DROP * h] / h) - 1)))
    keep &= ~stale
    if keep.all():
        return t, arrays, report
    return t[keep], {k: np.asarray(a)[keep] for k, a in arrays.items()}, report


def _gap_band(t, q, h: float, max_gap: float) -> float | None:
    """The band [Hz] of angles ``q`` (N, m) at stamps ``t`` (median step ``h``): where
    ``ENERGY_FRACTION`` of their power lies (:func:`jflex.data._signal.power_band`) over the
    longest stretch without a step over ``max_gap`` median steps, at its mean step (jitter and
    single dropped samples hardly move it; a band against the angle noise would, jitter reading as
    noise); None when that stretch is too short to tell (under 256 samples)."""
    q = np.asarray(q, float).reshape(t.size, -1)
    if not q.shape[1]:
        return None
    brk = np.flatnonzero(np.diff(t) > max_gap * h)
    edges = np.concatenate([[0], brk + 1, [t.size]])
    k = int(np.argmax(np.diff(edges)))
    lo, hi = int(edges[k]), int(edges[k + 1])
    if hi - lo < 256:
        return None
    band = power_band(q[lo:hi], float(np.mean(np.diff(t[lo:hi]))), ENERGY_FRACTION)
    return band if band > 0 else None


def _judge_gaps(t, arrays: dict, h: float, max_gap: float, motion: str | None):
    """The gaps of stamps ``t`` (median step ``h``): ``(indices k of the steps t[k] -> t[k + 1] over
    ``max_gap`` median steps, the motion's band [Hz] or None, the longest gap bridged [s])``; the
    longest bridged is ``BRIDGE`` of the shortest period of the motion (0 without a band)."""
    dt = np.diff(t)
    gaps = np.flatnonzero(dt > max_gap * h)
    if not gaps.size:
        return gaps, None, 0.0
    band = _gap_band(t, arrays[motion], h, max_gap) if motion is not None and motion in arrays else None
    return gaps, band, (BRIDGE / band if band else 0.0)


def resample_uniform(t, arrays: dict, where: str, *, jitter: float = JITTER, max_gap: float = MAX_GAP,
                     field: str = "t", motion: str | None = "q", bridge_s: float | None = None):
    """``t`` and ``arrays`` (rows at ``t``) as they are if every step is within ``jitter`` of the
    median step, else linearly interpolated onto a uniform grid whose step is the mean of the
    steps that dropped nothing (the median of jittered steps is a noisier estimate of the rate).

    A gap (a step over ``max_gap`` median steps) is bridged when it is shorter than ``BRIDGE`` of
    the shortest period of the motion (1 / the band holding ``ENERGY_FRACTION`` of the power of the
    angles ``arrays[motion]``, read off the longest stretch without a gap), or than ``bridge_s``
    [s] when given (the limit :func:`split_at_gaps` judged over the whole record a stretch was cut
    from); longer gaps, or any gap when there are no angles to judge it by, are refused, every one
    named with its time and length (:func:`split_at_gaps` cuts the log there into stretches).

    **Returns** ``(t, arrays, report)``: ``rate_hz``, ``jitter_pct`` (largest deviation from the
    median step of the steps that dropped nothing), ``longest_step`` (in median steps),
    ``dropped_samples`` (missing samples at steps over 1.5 median steps), ``resampled``, and
    ``gaps`` (every gap: ``t_s`` where it starts, ``length_s``, ``steps``) when there are any."""
    t = np.asarray(t, float)
    dt = np.diff(t)
    if t.size < 2 or np.all(dt == 0):
        raise DataError(f"{where}: field '{field}': the stamps are all equal ({t.size} row(s) at "
                        f"{t[0] if t.size else float('nan'):.9g} s); a time series needs increasing stamps")
    h = float(np.median(dt))
    if not h > 0:
        raise DataError(f"{where}: field '{field}': the median time step is {h:g} s (time must increase)")
    dev = float(np.max(np.abs(dt - h)) / h)
    drops = dt > DROP * h
    # the jitter is the clock's: a step over a dropped sample is counted as a drop, not as jitter
    # (a log with 20 % jitter and one burst of 3 lost samples read "jitter 300 %" otherwise)
    kept = np.abs(dt[~drops] - h) / h
    report = {"rate_hz": 1.0 / h, "jitter_pct": 100.0 * float(kept.max()) if kept.size else 0.0,
              "longest_step": float(dt.max() / h),
              "dropped_samples": int(np.sum(np.round(dt[drops] / h) - 1)), "resampled": False}
    if dev <= jitter:
        report["rate_hz"] = 1.0 / float(dt.mean())
        return t, arrays, report
    gaps, band, longest = _judge_gaps(t, arrays, h, max_gap, motion)
    if bridge_s is not None:
        longest = float(bridge_s)
    if gaps.size:
        report["gaps"] = [{"t_s": float(t[k]), "length_s": float(dt[k]), "steps": float(dt[k] / h)} for k in gaps]
        if band or bridge_s is not None:
            report["gap_bridge_limit_s"] = longest
        long = [k for k in gaps if dt[k] > longest]
        if long:
            if bridge_s is not None:
                why = f"longer than the {longest:.3g} s bridged in the record it was cut from"
            elif band:
                why = (f"longer than {BRIDGE:g} of the motion's shortest period ({longest:.3g} s, its band {band:.3g} "
                       "Hz): interpolation would invent the motion in it")
            else:
                why = "no angles to judge it against: interpolation could invent the data in it"
            named = "; ".join(f"a gap of {dt[k]:.6g} s after t = {t[k]:.6g} s ({dt[k] / h:.1f} median steps)" for k in long)
            raise DataError(f"{where}: field '{field}': {named}: {len(long)} gap(s) over {max_gap:g} median steps of "
                            f"{h:.6g} s {why}; cut the log at each into separate data sets")
        for g in report["gaps"]:
            g["action"] = "bridged by linear interpolation"
    step = float(np.mean(dt[~drops]))
    grid = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step * (1 + 1e-12))) + 1)
    out = {}
    for key, a in arrays.items():
        a = np.asarray(a, float)
        flat = a.reshape(t.size, -1)
        r = np.column_stack([np.interp(grid, t, flat[:, j]) for j in range(flat.shape[1])]) if flat.shape[1] \
            else np.zeros((grid.size, 0))
        out[key] = r.reshape((grid.size,) + a.shape[1:])
    report.update(rate_hz=1.0 / step, resampled=True, samples_in=int(t.size), samples_out=int(grid.size))
    return grid, out, report


def split_at_gaps(t, arrays: dict, where: str, *, max_gap: float = MAX_GAP, motion: str | None = "q"):
    """Where a log must be cut: at every gap :func:`resample_uniform` would refuse (over ``max_gap``
    median steps and longer than ``BRIDGE`` of the motion's shortest period, judged as it judges
    them, on the stamps :func:`clean_stamps` keeps), so that each stretch between them is a record
    of its own; the shorter gaps stay inside a stretch, to be bridged.

    **Returns** None when no gap needs a cut (the log is conditioned whole, as before), else
    ``(stretches, report)``: ``stretches`` a list, in time order, of ``(start_s, end_s)`` (the
    first and last kept stamps of each stretch: the rows of ``t`` within them, ends included, are
    the stretch's), and the report ``gaps`` (every gap: ``t_s``, ``length_s``, ``steps`` and the
    ``action``, ``split`` or ``bridged by linear interpolation``), ``gap_bridge_limit_s`` (the
    longest gap bridged, to pass to each stretch's :func:`resample_uniform` as ``bridge_s``: a
    stretch judged on its own could read another band) and ``motion_band_hz`` (None: no angles,
    or no stretch of 256 samples, to read it from; every gap is then cut)."""
    tc, ac, _ = clean_stamps(t, arrays, where)
    dt = np.diff(tc)
    if tc.size < 2 or not np.any(dt > 0):
        return None
    h = float(np.median(dt))
    if not h > 0 or float(np.max(np.abs(dt - h)) / h) <= JITTER:
        return None
    gaps, band, longest = _judge_gaps(tc, ac, h, max_gap, motion)
    cut = [int(k) for k in gaps if dt[k] > longest]
    if not cut:
        return None
    report = {"gaps": [{"t_s": float(tc[k]), "length_s": float(dt[k]), "steps": float(dt[k] / h),
                        "action": "split" if k in cut else "bridged by linear interpolation"} for k in gaps],
              "gap_bridge_limit_s": longest, "motion_band_hz": band}
    first = [0] + [k + 1 for k in cut]
    last = cut + [tc.size - 1]
    return [(float(tc[a]), float(tc[b])) for a, b in zip(first, last)], report


def merge_on_time(parts, where: str):
    """Several logs of one run merged on time: ``parts`` is a list of ``(label, t, {column: (N_k,)})``.
    Logs whose stamps agree (to 1e-9 of the step) are joined row by row; otherwise every log is
    interpolated linearly onto the first log's stamps within the span all logs cover.

    **Returns** ``(t, {column: (N,)}, report)``."""
    label0, t0, cols0 = parts[0]
    t0 = np.asarray(t0, float)
    same = all(np.asarray(t).shape == t0.shape and np.allclose(t, t0, rtol=0, atol=1e-9 * np.median(np.diff(t0)))
               for _, t, _ in parts[1:])
    out = dict(cols0)
    seen = {c: label0 for c in cols0}
    if same:
        for label, _, cols in parts[1:]:
            for c, v in cols.items():
                if c in seen:
                    raise DataError(f"{where}: column {c!r} is in both {seen[c]} and {label}")
                seen[c] = label
                out[c] = np.asarray(v, float)
        return t0, out, {"files": [p[0] for p in parts], "merged": "row by row (same stamps)"}
    lo = max(float(np.min(t)) for _, t, _ in parts)
    hi = min(float(np.max(t)) for _, t, _ in parts)
    if not hi > lo:
        raise DataError(f"{where}: the logs {[p[0] for p in parts]} share no time span")
    m = (t0 >= lo) & (t0 <= hi)
    out = {c: np.asarray(v, float)[m] for c, v in cols0.items()}
    for label, t, cols in parts[1:]:
        t = np.asarray(t, float)
        if np.any(np.diff(t) <= 0):
            raise DataError(f"{where}: {label}: time must increase to be merged by interpolation")
        for c, v in cols.items():
            if c in seen:
                raise DataError(f"{where}: column {c!r} is in both {seen[c]} and {label}")
            seen[c] = label
            out[c] = np.interp(t0[m], t, np.asarray(v, float))
    return t0[m], out, {"files": [p[0] for p in parts], "merged": f"interpolated onto the stamps of {label0}",
                        "span_s": [lo, hi]}


def _longest_run(x, moving=None) -> int:
    """Samples in the longest run of one held value (counting only samples where ``moving``)."""
    if x.size == 0:
        return 0
    run = np.concatenate([[0], np.cumsum(np.diff(x) != 0)])
    w = np.ones(x.size) if moving is None else np.asarray(moving, float)
    return int(np.bincount(run, weights=w).max())


def clipped_samples(x, moving=None) -> np.ndarray:
    """(N,) bool: the samples of ``x`` (N,) where it clips: runs at its largest or smallest value of
    at least ``CLIP_RUN`` samples, and longer than twice the longest hold of any other value (a
    quantised reading holds its levels too), counting only samples where ``moving`` (N,) bool when
    given (a robot at rest may hold a noise-free torque that is its extreme)."""
    x = np.asarray(x, float)
    out = np.zeros(x.size, bool)
    if x.size < 2 or not x.max() > x.min():
        return out
    run = np.concatenate([[0], np.cumsum(np.diff(x) != 0)])
    w = np.ones(x.size) if moving is None else np.asarray(moving, float)
    length = np.bincount(run, weights=w)
    value = x[np.searchsorted(run, np.arange(run[-1] + 1))]
    rail = (value == x.max()) | (value == x.min())
    other = float(length[~rail].max()) if (~rail).any() else 0.0
    clip = rail & (length >= max(CLIP_RUN, 2.0 * other + 1.0))
    return clip[run]


def channel_quality(x, fellow_std: float | None = None, moving=None) -> dict:
    """What is wrong with one channel ``x`` (N,): ``{"flags": [...], ...numbers}``.

    ``dead``: exactly zero in ``DEAD_ZEROS`` of the samples or more (a sensor switched off);
    ``flat``: constant, or its spread below ``FLAT_REL`` of ``fellow_std`` (the median spread of
    the other channels of its kind); ``stuck``: one value held in a single run of ``STUCK_RUN`` of
    the record while the robot moves (``moving`` (N,) bool, when given: a robot at rest may hold
    a noise-free torque); ``saturated``: clipping (:func:`clipped_samples`: held at its largest or
    smallest value for more than a few samples; ``clipped_fraction`` of the samples, which are
    masked, the rest of the channel kept); ``few_levels``: fewer than ``FEW_LEVELS`` distinct values."""
    x = np.asarray(x, float)
    n = max(x.size, 1)
    zeros = float(np.mean(x == 0.0))
    std = float(x.std())
    levels = int(np.unique(x).size)
    run = _longest_run(x, moving) / n
    rail = max(float(np.mean(x == x.max())), float(np.mean(x == x.min()))) if x.size else 0.0
    flags = []
    if zeros >= DEAD_ZEROS:
        flags.append("dead")
    if std == 0.0 or std <= 1e-12 * abs(float(x.mean())) or (fellow_std and std < FLAT_REL * fellow_std):
        flags.append("flat")
    elif run >= STUCK_RUN and "dead" not in flags:
        flags.append("stuck")
    if levels < FEW_LEVELS and std > 0 and "dead" not in flags:
        flags.append("few_levels")
    clipped = clipped_samples(x, moving) if levels >= FEW_LEVELS and "dead" not in flags else np.zeros(x.size, bool)
    if clipped.any():
        flags.append("saturated")
    return {"flags": flags, "zero_fraction": zeros, "std": std, "levels": levels, "longest_run_fraction": run,
            "at_extreme_fraction": rail, "clipped_fraction": float(clipped.mean()) if x.size else 0.0,
            "clipped": clipped}


def angle_jumps(t, q, where: str, names=None) -> None:
    """Refuse angles ``q`` (N, m) at stamps ``t`` that jump in one sample: a step over ``JUMP`` x
    every other step within ``JUMP_WINDOW`` samples of it and over ``JUMP`` x the column's ordinary
    moving step (the ``JUMP_QUANTILE`` of its nonzero steps); ``names`` (m,) the columns' joints. A log spliced from two runs, or an angle that wraps, puts
    an impulse into every derivative the diagnosis takes there; motion, however fast, changes its
    step gradually. The error names each such sample and its time."""
    q = np.asarray(q, float).reshape(t.size, -1)
    if t.size < 3:
        return
    d = np.abs(np.diff(q, axis=0))
    found = []
    for j in range(q.shape[1]):
        dj = d[:, j]
        nz = dj[dj > 0]
        if nz.size < 2:
            continue
        # the largest step around each one, itself left out
        W = JUMP_WINDOW
        pad = np.lib.stride_tricks.sliding_window_view(np.r_[np.zeros(W), dj, np.zeros(W)], 2 * W + 1)
        near = np.maximum(pad[:, :W].max(axis=1), pad[:, W + 1:].max(axis=1))
        # and over JUMP x the column's ordinary moving step (its JUMP_QUANTILE): against the smallest
        # step (an encoder's count), a log that keeps 5 significant digits (FIGAROH's TX40: a
        # count of 9.5e-5 rad near zero, 2.1e-4 rad at 100 rad) read the first count after each
        # rest as a splice and was refused whole
        typical = float(np.quantile(nz, JUMP_QUANTILE))
        for k in np.flatnonzero((dj > JUMP * near) & (dj > JUMP * typical)):
            found.append((int(k) + 1, j, float(q[k + 1, j] - q[k, j]), float(near[k])))
    if found:
        found.sort()
        label = (lambda j: f"joint {names[j]}") if names is not None and len(names) == q.shape[1] else \
            (lambda j: f"column {j}")
        named = "; ".join(f"{label(j)} at sample {k} (t = {t[k]:.6g} s): {dq:+.4g} rad against steps of at most "
                          f"{typ:.3g} rad around it" for k, j, dq, typ in found[:10])
        more = f" and {len(found) - 10} more" if len(found) > 10 else ""
        raise DataError(f"{where}: field 'q': the angle jumps in one sample, {named}{more}: a log spliced from "
                        "separate runs (or an angle that wraps); cut the log there into separate data sets")


def find_spikes(x) -> np.ndarray:
    """Indices of isolated spikes in ``x`` (N,): samples more than ``SPIKE_SIGMA`` robust standard
    deviations off the running median of ``SPIKE_WINDOW`` samples (a running median keeps steps,
    such as friction reversing, and removes single-sample outliers). The scale is the larger of
    the residual's spread (MAD) and the sample-to-sample step's (MAD / sqrt 2), each taken both
    over the record and locally (running medians over ``SPIKE_SCALE_WINDOW`` samples): a log
    that rests for most of its length has a near-zero spread over the record, against which the
    ordinary noise of its moving part would all count as spikes."""
    from scipy.ndimage import maximum_filter, median_filter

    x = np.asarray(x, float)
    if x.size < 3 * SPIKE_WINDOW:
        return np.zeros(0, int)
    r = x - median_filter(x, size=SPIKE_WINDOW, mode="nearest")
    # the larger of two robust scales: the spread of the residual off the running median (noise),
    # and that of the sample-to-sample step (a smooth, fast signal bends off its running median)
    d = np.diff(x)
    sig = max(float(robust_sigma(r)), float(robust_sigma(d)) / np.sqrt(2.0))
    w = min(SPIKE_SCALE_WINDOW, x.size) | 1
    local = np.maximum(1.4826 * median_filter(np.abs(r), size=w, mode="nearest"),
                       1.4826 / np.sqrt(2.0) * median_filter(np.abs(np.r_[d, d[-1]]), size=w, mode="nearest"))
    # where the noise level changes (motion stopping), the louder side's scale holds over a window
    scale = np.maximum(maximum_filter(local, size=w, mode="nearest"), sig)
    if not np.any(scale > 0.0):
        return np.zeros(0, int)
    return np.flatnonzero((scale > 0.0) & (np.abs(r) > SPIKE_SIGMA * scale))


def replace_by_interpolation(x, idx) -> np.ndarray:
    """``x`` with the samples ``idx`` replaced by linear interpolation between their neighbours."""
    x = np.asarray(x, float).copy()
    if len(idx):
        good = np.ones(x.size, bool)
        good[idx] = False
        x[idx] = np.interp(np.flatnonzero(~good), np.flatnonzero(good), x[good])
    return x


def condition_torque(t, arrays: dict, joints, where: str, *, keep=(), replace_spikes: bool = False,
                     bridge_s: float | None = None):
    """Condition one torque record: stamps cleaned and made uniform, torque channels checked.

    ``arrays``: ``q`` (N, m), ``tau`` (N, n) with ``joints`` (n,) naming the torque columns,
    optional ``qd``/``qdd``/``q_extra`` rows. Torque channels flagged by :func:`channel_quality`
    with one of ``EXCLUDE_FLAGS`` are listed as excluded unless their joint is in ``keep``.
    Spikes are counted per channel and replaced only when ``replace_spikes``. ``bridge_s``: the
    longest gap bridged, for a stretch :func:`split_at_gaps` cut from a longer log (see
    :func:`resample_uniform`).

    **Returns** ``(t, arrays, report, excluded)``: the report holds ``sampling`` (the stamps:
    rate, jitter, drops, repeats, resampled), ``channels`` (per torque joint: flags and the
    numbers behind them), ``spikes`` and ``derivatives`` (``given``, ``velocity`` (velocities
    without accelerations: filtered before differentiation) or ``none``); ``excluded`` the
    joints left out of the gap."""
    rows = {k: v for k, v in arrays.items() if np.ndim(v) >= 1 and np.shape(v)[0] == np.size(t)}
    rest = {k: v for k, v in arrays.items() if k not in rows}
    t, rows, rep_stamps = clean_stamps(t, rows, where)
    t, rows, rep_rate = resample_uniform(t, rows, where, bridge_s=bridge_s)
    angle_jumps(t, rows["q"], where, joints)
    report = {"sampling": {**rep_rate, **rep_stamps}}
    tau = np.asarray(rows["tau"], float).copy()
    stds = tau.std(axis=0)
    q = np.asarray(rows["q"], float)
    moving = np.concatenate([[False], np.any(np.diff(q, axis=0) != 0, axis=1)]) if q.shape[1] else None
    channels, spikes, excluded = {}, {}, []
    valid = np.ones(tau.shape, bool)
    for k, j in enumerate(joints):
        others = np.delete(stds, k)
        fellow = float(np.median(others)) if others.size else None
        qual = channel_quality(tau[:, k], fellow, moving)
        clipped = qual.pop("clipped")
        bad = [f for f in qual["flags"] if f in EXCLUDE_FLAGS]
        if clipped.any() and j not in keep:
            valid[:, k] = ~clipped
            qual["clipped_from_s"] = float(t[np.argmax(clipped)])
        if bad and j not in keep:
            excluded.append(j)
        elif not bad:
            idx = find_spikes(tau[:, k])
            if idx.size:
                spikes[j] = {"count": int(idx.size), "first_s": float(t[idx[0]]),
                             "action": "replaced by interpolation" if replace_spikes else "flagged"}
                qual["flags"].append("spikes")
                if replace_spikes:
                    tau[:, k] = replace_by_interpolation(tau[:, k], idx)
        qual["kept_by_user"] = bool(bad) and j in keep
        channels[j] = qual
    rows["tau"] = tau
    if not valid.all():
        # the clipped samples, masked in every fit and in the gap (jflex.gap.torque_set)
        rows["tau_valid"] = valid
    report["channels"] = channels
    report["spikes"] = spikes
    report["excluded"] = list(excluded)
    report["derivatives"] = "given" if ("qd" in rows and "qdd" in rows) else "velocity" if "qd" in rows else "none"
    return t, {**rows, **rest}, report, tuple(excluded)


def _power_edge(f, P, share: float) -> float:
    """The highest, over the columns of a spectrum ``P`` (F, n), of the frequency below which
    ``share`` of the column's power lies (columns without power are skipped; 0 when none has)."""
    edges = []
    for p in P.T:
        c = np.cumsum(p)
        if c[-1] > 0:
            edges.append(float(f[min(int(np.searchsorted(c, share * c[-1])), f.size - 1)]))
    return max(edges, default=0.0)


def choose_cutoff(q, dt: float, *, qd=None, factor: float = CUTOFF_FACTOR, decimate: int = 1,
                  limit: float = CUTOFF_LIMIT, resampled: bool = False):
    """The low-pass cutoff [Hz] of one record, from its own angle spectrum, always inside
    ``(0, limit x Nyquist)`` (the Nyquist frequency after ``decimate``).

    First ``factor`` x the motion's band (:func:`jflex.data._signal.motion_band`: where the angle
    spectrum stands above the angle noise). When that gives no answer (nothing above the noise, or a
    band whose cutoff would not lie below ``limit`` x Nyquist: quantised, pre-filtered or
    interpolated angles, whose sample-to-sample noise estimate is too low), the fallback
    ``spectrum_floor``: ``factor`` x the highest frequency (below half the Nyquist frequency) where
    the angle spectrum stands ``FLOOR_SNR`` above its own median level over (0.5, ``limit``) x
    Nyquist, or, when lower, where every column has all but ``TAIL_FRACTION`` of its power (a
    spectrum that decays smoothly into a far lower floor). When that gives no answer either, ``energy``: ``factor`` x the frequency below which
    ``ENERGY_FRACTION`` of the detrended angles' power lies (of ``qd`` when given). Should that too
    reach the limit, the cutoff is the limit itself (``limit``).

    **Returns** ``(cutoff, info)``: info names the ``method`` and holds ``motion_band_hz``,
    ``nyquist_hz`` and ``angle_noise_rad``. ``resampled``: the angles were resampled from jittered
    stamps (:func:`jflex.data._signal.motion_band`)."""
    from scipy.signal import detrend, welch

    q = np.asarray(q, float)
    nyq = float(0.5 / (dt * max(int(decimate), 1)))
    top = limit * nyq
    sig = angle_noise(q)
    f_m = motion_band(q, dt, sig, resampled=resampled)
    nper = min(q.shape[0], 1024)
    df = 1.0 / (dt * nper)
    # a band held by the angles' power was read in finer frequency steps
    df_m = 1.0 / (dt * power_segment(q.shape[0], dt, POWER_RESOLUTION)) if held_by_power(q, resampled) else df
    info = {"motion_band_hz": f_m, "nyquist_hz": nyq, "limit_hz": top, "angle_noise_rad": sig.tolist()}
    fc = factor * f_m
    if f_m > 1.5 * df_m and fc < top:
        return fc, {**info, "method": "motion_band"}
    f, P = welch(detrend(q, axis=0), fs=1.0 / dt, nperseg=nper, window="blackmanharris", axis=0)
    # fallback 1, "spectrum_floor": the angle noise as the spectrum itself shows it (its median
    # level over the top of the band), not as the sample-to-sample spread estimates it
    top_band = (f > 0.5 * nyq) & (f < top)
    if top_band.sum() >= 3:
        floor = np.median(P[top_band], axis=0)
        above = (P > FLOOR_SNR * floor[None, :]).any(axis=1) & (f > 0)
        above &= f < 0.5 * nyq
        if above.any():
            f_s = float(f[np.flatnonzero(above)[-1]])
            info["floor_band_hz"] = f_s
            # a spectrum that decays smoothly into a floor far below it (fine encoders, the
            # f^-4 tail of servoed motion) stands above that floor long after the motion's power
            # has ended (a 5 kHz arm log: 176 Hz against 99.9999 % of its power below 59 Hz), so
            # the band also ends where every column has all but TAIL_FRACTION of its power
            edge = _power_edge(f, P, 1.0 - TAIL_FRACTION)
            info["power_edge_hz"] = edge
            if 1.5 * df < edge < f_s:
                f_s = edge
            fc = factor * f_s
            if f_s > 1.5 * df and fc < top:
                return fc, {**info, "method": "spectrum_floor"}
    # fallback 2, "energy": where the angles' (or rates') power ends
    x = np.asarray(qd, float) if qd is not None else q
    f, P = welch(detrend(x, axis=0), fs=1.0 / dt, nperseg=nper, axis=0)
    f_e = _power_edge(f, P.sum(axis=1, keepdims=True), ENERGY_FRACTION)
    info["energy_band_hz"] = f_e
    fc = factor * max(f_e, df)
    if fc < top:
        return fc, {**info, "method": "energy"}
    return top * (1 - 1e-9), {**info, "method": "limit"}


def currents_to_torque(i, k, i0=None, coupling=None, offset=None) -> np.ndarray:
    """Joint torques from motor currents: ``tau = K^T (k (i - i0)) + offset``, row by row.

    ``i`` (N, m) motor currents (or any raw unit); ``k`` (m,) factors to motor torque on the joint
    side (torque constant x gear ratio); ``i0`` (m,) current offsets; ``coupling`` ``K`` (m, n):
    the motor rates are ``K qd``, so the joint torques are ``K^T`` times the motor torques
    (identity: one motor per joint); ``offset`` (n,) joint torque offsets [N m]."""
    i = np.asarray(i, float)
    m = i.shape[1]
    k = np.broadcast_to(np.asarray(k, float), (m,))
    i0 = np.zeros(m) if i0 is None else np.broadcast_to(np.asarray(i0, float), (m,))
    motor = (i - i0[None, :]) * k[None, :]
    tau = motor if coupling is None else motor @ np.asarray(coupling, float)
    if offset is not None:
        tau = tau + np.broadcast_to(np.asarray(offset, float), (tau.shape[1],))[None, :]
    return tau
