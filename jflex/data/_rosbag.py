"""ROS 2 bags and MCAP logs: the ``sensor_msgs/msg/JointState`` messages of one topic read into
the arrays an NPZ data set holds (``t``, ``q``, ``tau``, optional ``qd``); the case loader then
checks them like any NPZ.

The reader is ``rosbags`` (the ``ros`` extra: no ROS install needed), imported only here and only
when a case names a bag, so the library imports without it. Joints are matched by the message's
``name`` field, so a driver may publish them in any order and with joints the model lacks (kept
as posture variables, like a CSV's extra position columns).

Time is the header stamp, or the bag's receive time when every stamp is zero, counted from the
first message (integer nanoseconds subtracted first: epoch seconds as floats keep only about
0.2 microseconds). A torque log keeps its stamps: the case loader conditions them as it does a
CSV log's (jittered stamps resampled, a gap short against the motion bridged, a longer one cutting
the log into data sets, every gap reported). A response log is resampled here: stamps that jitter
by more than 1 % of the median step go onto a uniform grid by linear interpolation, and a gap
over 5 median steps that the motion does not allow to bridge is refused.
"""

from __future__ import annotations

import pathlib

import numpy as np

from .._errors import ConfigError, DataError
from ._condition import JITTER as JITTER, MAX_GAP as MAX_GAP, resample_uniform
from ._log_map import LogMap
from ._record import Channel, Record

TOPIC = "/joint_states"
MSGTYPE = "sensor_msgs/msg/JointState"


def _messages(path: pathlib.Path, topic: str, case_file, fld: str) -> list:
    """(receive time [ns], stamp [ns], name, position, velocity, effort) of each message on ``topic``."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise DataError(f"{case_file}: field '{fld}.file': {path.name} is a ROS 2 bag; reading it needs the "
                        'rosbags package: pip install "jflex[ros]"') from None
    try:
        # bags store their message definitions (MCAP, sqlite3 from Iron on); the typestore is
        # for older ones that do not
        with AnyReader([path], default_typestore=get_typestore(Stores.LATEST)) as reader:
            cons = [c for c in reader.connections if c.topic == topic]
            if not cons:
                raise DataError(f"{path}: field '{fld}.topic': no topic {topic!r} in the bag "
                                f"(its topics: {sorted(reader.topics)})")
            types = sorted({c.msgtype for c in cons})
            if types != [MSGTYPE]:
                raise DataError(f"{path}: field '{fld}.topic': topic {topic!r} carries {types}, expected {MSGTYPE}")
            out = []
            for con, ns, raw in reader.messages(connections=cons):
                m = reader.deserialize(raw, con.msgtype)
                stamp = int(m.header.stamp.sec) * 10**9 + int(m.header.stamp.nanosec)
                out.append((int(ns), stamp, list(m.name), np.asarray(m.position, float),
                            np.asarray(m.velocity, float), np.asarray(m.effort, float)))
            return out
    except AnyReaderError as exc:
        raise DataError(f"{path}: field '{fld}.file': not a readable ROS 2 bag ({exc})") from None


def _time(msgs, where: str) -> np.ndarray:
    """Each message's time [ns]: the header stamp, or the receive time when no message is stamped."""
    stamp = np.array([m[1] for m in msgs], dtype=np.int64)
    zero = stamp == 0
    if zero.all():
        return np.array([m[0] for m in msgs], dtype=np.int64)
    if zero.any():
        raise DataError(f"{where}, message {int(np.argmax(zero))}: field 'header.stamp': zero while other messages "
                        "are stamped (stamp every message, or none: then the bag's receive time is used)")
    return stamp


def read_rosbag(path: pathlib.Path, m: LogMap) -> Record:
    """The :class:`Record` of the ROS 2 bag ``path`` read as the log map ``m`` says: torque data
    ``t``, ``q`` (and ``joints``), ``tau``, ``qd`` when every message has
    velocities; response data ``t``, ``tau``, ``y`` (the model joints' angles) and ``channels``.
    Efforts pass ``offset`` (joint -> raw offset), ``scale``, ``coupling`` and ``torque_offset``
    as a CSV's torque columns do."""
    case_file, fld = m.where
    if not path.exists():
        raise ConfigError(f"{case_file}: field '{fld}.file': data file {path} not found")
    topic = m.topic or TOPIC
    names = list(m.joints)
    scale = m.scale or {}
    offset = m.offset or {}
    for key, factors in (("scale", scale), ("offset", offset)):
        for j in factors:
            if j not in names:
                raise ConfigError(f"{case_file}: field '{fld}.{key}.{j}': {j!r} is not a model joint (a bag's {key} "
                                  f"applies to the effort of a joint; model joints {names})")
    msgs = _messages(path, topic, case_file, fld)
    where = f"{path}: topic {topic!r}"
    if len(msgs) < 2:
        raise DataError(f"{where}: {len(msgs)} messages (a {m.kind} data set is a time series)")
    # joints the model lacks: kept as posture variables (torque data)
    joints = names + [j for j in msgs[0][2] if j not in names] if m.kind == "torque" else names
    rates = m.kind == "torque" and all(m[4].size for m in msgs)
    q, qd, tau = [], [], []
    for k, (_, _, nm, pos, vel, eff) in enumerate(msgs):
        col = {j: i for i, j in enumerate(nm)}
        missing = [j for j in joints if j not in col]
        if missing:
            what = "model joints" if any(j in names for j in missing) else "joints of the first message"
            raise DataError(f"{where}, message {k}: field 'name': no {what} {missing} (it names {nm}; "
                            f"model joints {names})")
        if eff.size == 0:
            raise DataError(f"{where}, message {k}: field 'effort': empty (a {m.kind} data set needs the joint "
                            "torques, or motor currents with a scale)")
        for field, arr in (("position", pos), ("effort", eff)) + ((("velocity", vel),) if rates else ()):
            if arr.size != len(nm):
                raise DataError(f"{where}, message {k}: field '{field}': {arr.size} values for {len(nm)} names")
        idx = [col[j] for j in joints]
        q.append(pos[idx])
        tau.append((eff[idx[:len(names)]] - np.array([offset.get(j, 0.0) for j in names]))
                   * np.array([scale.get(j, 1.0) for j in names]))
        if rates:
            qd.append(vel[idx])
    ns = _time(msgs, where)
    order = np.argsort(ns, kind="stable")
    ns = ns[order]
    same = np.flatnonzero(np.diff(ns) == 0)
    if same.size:
        raise DataError(f"{where}, messages {order[same[0]]} and {order[same[0] + 1]}: field 'header.stamp': the "
                        "same time (a time series needs strictly increasing stamps)")
    t = (ns - ns[0]) * 1e-9
    from ._csv import motor_angles, transmission

    arrays = {"q": motor_angles(np.asarray(q)[order], names, m),
              "tau": transmission(np.asarray(tau)[order], names, m)}
    if rates:
        arrays["qd"] = motor_angles(np.asarray(qd)[order], names, m)
    cond = {}
    if m.kind == "response":
        t, arrays, cond["sampling"] = resample_uniform(t, arrays, where, field="header.stamp")
    channels = {f"q:{j}": Channel(f"q:{j}", "rad", f"{path.name}:{topic}:position[{j}]") for j in joints}
    channels.update({f"tau:{j}": Channel(f"tau:{j}", "N m", f"{path.name}:{topic}:effort[{j}]", scale.get(j, 1.0),
                                         offset.get(j, 0.0)) for j in names})
    if m.kind == "response":
        return Record({"t": t, "tau": arrays["tau"], "y": arrays["q"], "channels": np.asarray(names)}, channels, cond)
    return Record({"t": t, **arrays, "joints": np.asarray(joints)}, channels, cond)


def rosbag_arrays(path: pathlib.Path, m: LogMap) -> dict:
    """The NPZ fields of a ROS 2 bag data set (:func:`read_rosbag` without the metadata)."""
    return read_rosbag(path, m).arrays
