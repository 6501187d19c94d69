"""What a reader needs to know of a log besides its file: what kind of record it holds, where
each quantity is (a plain column map), the scale and offset of raw columns, the transmission's
coupling, units, and the label its messages name a mistake by. The case layer translates a
case.yaml data set into one (:func:`jflex.gap.load_case`); the readers know nothing of case.yaml."""

from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class LogMap:
    """How to read one log into a :class:`Record`.

    - ``kind``: ``"torque"``, ``"response"``, ``"frf"`` or ``"modal"``.
    - ``columns``: quantity -> column name, or -> {joint (or channel): column} (CSV): ``time``,
      ``position``, ``velocity``, ``acceleration``, ``torque``, ``output``, ``frequency``,
      ``damping_ratio``; a quantity the log lacks is left out or None.
    - ``joints``: the model's joint names, in its order.
    - ``scale``, ``offset``: raw column (a bag: joint) -> factor, and offset subtracted first.
    - ``coupling``: ``{"joints": [...], "matrix": K, "angles": "joint" | "motor"}`` of a coupled
      transmission, or None; ``torque_offset``: joint -> torque [N m] added last.
    - ``time_unit`` (s, ms, us, ns), ``position_unit`` (rad, deg); ``rate`` [Hz] of a log
      without a time column; ``delimiter`` of a CSV (None: sniffed).
    - ``q0``: the posture a log without one states (a list in joint order, or joint -> angle);
      ``quantity``: what a UFF's records hold (None: read off their units); ``topic`` of a bag.
    - ``where``: ``(source, field)`` its messages name, e.g. the case file and ``datasets[0]``.
    """

    kind: str
    columns: dict = dataclasses.field(default_factory=dict)
    joints: tuple = ()
    scale: dict = dataclasses.field(default_factory=dict)
    offset: dict = dataclasses.field(default_factory=dict)
    coupling: dict | None = None
    torque_offset: dict = dataclasses.field(default_factory=dict)
    time_unit: str = "s"
    position_unit: str = "rad"
    rate: float | None = None
    delimiter: str | None = None
    q0: list | dict | None = None
    quantity: str | None = None
    topic: str | None = None
    where: tuple = ("log", "data")
