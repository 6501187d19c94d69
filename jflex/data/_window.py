"""A time window of a record: the samples whose stamps lie in ``[start, end]`` seconds from the
first, and the record cut to them (every array with a time axis: the first one, the second one of
``*_repeats``)."""

from __future__ import annotations

import numpy as np


def window_mask(t, window) -> np.ndarray:
    """The samples of the stamps ``t`` inside ``window`` = [start, end] seconds from the first
    stamp (``end`` None: to the end); ``jflex case init --hold-out`` checks its split with it."""
    t = np.asarray(t, float)
    start, end = window
    rel = t - t[0]
    return (rel >= start) & (rel <= (np.inf if end is None else end))


def window_rows(arrs: dict, keep) -> dict:
    """The arrays of a time record (``t`` and every array with a time axis) at the samples ``keep``
    ((N,) bool over ``arrs["t"]``); arrays without a time axis as they are."""
    t = np.asarray(arrs["t"], float)
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
