"""The record type of the data layer: the arrays a reader produced, what each channel is, and
what the conditioning did to them."""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Channel:
    """One measured channel: ``name`` (``"tau:joint2"``: the field and the joint), its ``unit`` after
    conversion (SI), the ``source`` it was read from (a CSV column, a bag's joint, an NPZ field),
    the ``scale`` and ``offset`` applied (``value = scale * (raw - offset)``, before any coupling),
    and the ``flags`` the conditioning raised (``dead``, ``flat``, ``stuck``, ``few_levels``: left out
    of the gap; ``saturated``: its clipped samples masked, the rest kept; ``spikes``)."""

    name: str
    unit: str
    source: str
    scale: float = 1.0
    offset: float = 0.0
    flags: tuple[str, ...] = ()


@dataclasses.dataclass
class Record:
    """What a reader gives: ``arrays`` in the fields an NPZ data set holds (``t``, ``q``, ``tau``,
    ... in SI units), ``channels`` (``{name: Channel}``) and ``conditioning`` (what was done to
    the samples, for the report)."""

    arrays: dict
    channels: dict = dataclasses.field(default_factory=dict)
    conditioning: dict = dataclasses.field(default_factory=dict)

    def flag(self, name: str, *flags: str) -> None:
        """Add ``flags`` to the channel ``name`` (created with unknown unit if it was not declared)."""
        c = self.channels.get(name) or Channel(name, "", name)
        new = tuple(dict.fromkeys(c.flags + tuple(flags)))
        self.channels[name] = dataclasses.replace(c, flags=new)


def channels_of(arrays: dict, source: str, names=None) -> dict:
    """Channel metadata of NPZ-style arrays read as they are (no scale, no offset): ``q`` [rad],
    ``qd`` [rad/s], ``qdd`` [rad/s^2], ``tau`` [N m] per column, named by ``names`` (or the index)."""
    units = {"q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau": "N m"}
    out = {}
    for field, unit in units.items():
        a = arrays.get(field)
        if a is None or np.ndim(a) != 2:
            continue
        for k in range(np.shape(a)[1]):
            j = names[k] if names is not None and k < len(names) else str(k)
            out[f"{field}:{j}"] = Channel(f"{field}:{j}", unit, f"{source}:{field}[:, {k}]")
    return out
