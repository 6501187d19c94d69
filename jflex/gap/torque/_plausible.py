"""What a fitted torque term is judged against: the sentence a value outside its plausible range is
reported with, and the scale of the data the ranges are relative to."""

from __future__ import annotations

import numpy as np

from ...effects._linear import DataScale


def out_of_range(name: str, value: float, lo: float, hi: float, unit: str = "", why: str = "") -> str | None:
    """The sentence a fitted value outside ``[lo, hi]`` is reported with (None inside)."""
    if lo <= value <= hi:
        return None
    u = f" {unit}" if unit else ""
    return f"{name} = {value:.4g}{u} lies outside the plausible range [{lo:.4g}, {hi:.4g}]{u}" + (f" ({why})" if why else "")


def data_scale(sets) -> DataScale:
    """What plausible ranges are relative to (:class:`jflex.effects.DataScale`), over the torque sets."""
    cat = lambda name: np.concatenate([getattr(s, name) for s in sets])
    dt = min(float(np.median(np.diff(s.t))) for s in sets)
    sc = DataScale.of(np.array([0.0, dt]), cat("qd"), cat("qdd"), cat("tau"))
    return sc._replace(model_rms=np.sqrt(np.mean(cat("F0") ** 2, axis=0)))
