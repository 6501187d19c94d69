"""Peak picking on an FRF magnitude: natural frequencies at its peaks and damping ratios by the
half-power bandwidth, ``zeta = (f_2 - f_1) / (2 f_n)`` with ``f_1, f_2`` where the magnitude
crosses ``peak / sqrt(2)`` (Ewins, "Modal Testing: Theory, Practice and Application")."""

from __future__ import annotations

import numpy as np

HALF_POWER = ("interpolated", "grid")


def pick_peaks(freq, mag, prominence: float, *, search=None, n_modes: int | None = None,
               half_power: str = "interpolated"):
    """Peaks of the magnitude ``mag`` (nf,) at the frequencies ``freq`` (nf,) [Hz], found
    (``scipy.signal.find_peaks``) on ``search`` (default ``mag``; e.g. ``mag`` zeroed outside a
    band) with a prominence of ``prominence`` x its largest value; ``n_modes``: keep the most
    prominent. From each peak the half-power points are walked to on ``mag``:

    - ``half_power="interpolated"``: each crossing interpolated linearly between its grid lines
      and the peak refined by a parabola through its three bins; zeta NaN (and the peak at its
      grid line) when a crossing falls off the band.
    - ``"grid"``: the first grid line at or below the half-power level each side, the peak at its
      grid line; zeta NaN when the walk reaches an end of the band.

    **Returns** ``(f_n (k,) [Hz], zeta (k,), index (k,))``, sorted by frequency."""
    import scipy.signal

    if half_power not in HALF_POWER:
        raise ValueError(f"pick_peaks: half_power is one of {HALF_POWER}, got {half_power!r}")
    A = mag
    Am = mag if search is None else search
    pk, props = scipy.signal.find_peaks(Am, prominence=prominence * Am.max())
    if n_modes is not None and len(pk) > n_modes:
        pk = np.sort(pk[np.argsort(-props["prominences"])[:n_modes]])
    fn, zeta = [], []
    for k in pk:
        half = A[k] / np.sqrt(2)
        i = k
        while i > 0 and A[i] > half:
            i -= 1
        j = k
        while j < len(A) - 1 and A[j] > half:
            j += 1
        if half_power == "grid":
            fn.append(freq[k])
            zeta.append((freq[j] - freq[i]) / (2 * freq[k]) if i > 0 and j < len(A) - 1 else np.nan)
            continue
        if A[i] > half or A[j] > half:
            zeta.append(np.nan)
        else:
            f1 = freq[i] + (half - A[i]) * (freq[i + 1] - freq[i]) / (A[i + 1] - A[i])
            f2 = freq[j - 1] + (half - A[j - 1]) * (freq[j] - freq[j - 1]) / (A[j] - A[j - 1])
            # Refine the peak by a parabola through the three bins around it.
            fn_k = freq[k]
            if 0 < k < len(A) - 1:
                a, b, c = A[k - 1], A[k], A[k + 1]
                d = a - 2 * b + c
                if d != 0:
                    fn_k = freq[k] + 0.5 * (a - c) / d * (freq[k + 1] - freq[k])
            zeta.append((f2 - f1) / (2 * fn_k))
            fn.append(fn_k)
            continue
        fn.append(freq[k])
    return np.asarray(fn), np.asarray(zeta), np.asarray(pk)
