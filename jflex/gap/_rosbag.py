"""ROS 2 bags and MCAP logs: the ``sensor_msgs/msg/JointState`` messages of one topic read into
the arrays an NPZ data set holds (``t``, ``q``, ``tau``, optional ``qd``); the case loader then
checks them like any NPZ.

The reader is ``rosbags`` (the ``ros`` extra: no ROS install needed), imported only here and only
when a case names a bag, so the library imports without it. Joints are matched by the message's
``name`` field, so a driver may publish them in any order and with joints the model lacks (kept
as posture variables, like a CSV's extra position columns).

Time is the header stamp, or the bag's receive time when every stamp is zero, counted from the
first message (integer nanoseconds subtracted first: epoch seconds as floats keep only about
0.2 microseconds). Stamps that jitter by more than 1 % of the median step are resampled onto a
uniform grid of that step by linear interpolation: an angle-only log is filtered and
differentiated, which needs uniform sampling. A gap over 5 median steps is refused rather than
bridged.
"""

from __future__ import annotations

import pathlib

import numpy as np

from .._errors import ConfigError, DataError

TOPIC = "/joint_states"
MSGTYPE = "sensor_msgs/msg/JointState"
JITTER = 0.01  # largest deviation of a step from the median step kept as it is (relative)
MAX_GAP = 5.0  # longest step (in median steps) resampling may bridge: beyond, it would invent data


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


def _uniform(t: np.ndarray, arrays: dict, where: str) -> tuple[np.ndarray, dict]:
    """``t`` and ``arrays`` (rows at ``t``) as they are if the steps agree to :data:`JITTER`, else
    linearly interpolated onto a uniform grid: the mean step, steps over 1.5 median steps (dropped
    messages) left out (the median of jittered steps is a noisier estimate of the rate)."""
    dt = np.diff(t)
    h = float(np.median(dt))
    if np.max(np.abs(dt - h)) <= JITTER * h:
        return t, arrays
    k = int(np.argmax(dt))
    if dt[k] > MAX_GAP * h:
        raise DataError(f"{where}: field 'header.stamp': a gap of {dt[k]:.6g} s after t = {t[k]:.6g} s "
                        f"({dt[k] / h:.1f} median steps of {h:.6g} s); resampling would invent the data in it "
                        "(cut the log there into two data sets)")
    h = float(np.mean(dt[dt <= 1.5 * h]))
    grid = t[0] + h * np.arange(int(np.floor((t[-1] - t[0]) / h * (1 + 1e-12))) + 1)
    return grid, {key: np.column_stack([np.interp(grid, t, a[:, j]) for j in range(a.shape[1])])
                  for key, a in arrays.items()}


def rosbag_arrays(path: pathlib.Path, spec, robot, case_file, fld: str) -> dict:
    """The NPZ fields of the ROS 2 bag data set ``spec`` (a validated ``datasets[i]`` of case.yaml):
    torque data ``t``, ``q`` (and ``joints``), ``tau``, ``qd`` when every message has velocities;
    response data ``t``, ``tau``, ``y`` (the model joints' angles) and ``channels``."""
    if not path.exists():
        raise ConfigError(f"{case_file}: field '{fld}.file': data file {path} not found")
    topic = spec.topic or TOPIC
    names = list(robot.joint_names)
    scale = spec.scale or {}
    for j in scale:
        if j not in names:
            raise ConfigError(f"{case_file}: field '{fld}.scale.{j}': {j!r} is not a model joint (a bag's scale "
                              f"multiplies the effort of a joint; model joints {names})")
    msgs = _messages(path, topic, case_file, fld)
    where = f"{path}: topic {topic!r}"
    if len(msgs) < 2:
        raise DataError(f"{where}: {len(msgs)} messages (a {spec.kind} data set is a time series)")
    # joints the model lacks: kept as posture variables (torque data)
    joints = names + [j for j in msgs[0][2] if j not in names] if spec.kind == "torque" else names
    rates = spec.kind == "torque" and all(m[4].size for m in msgs)
    q, qd, tau = [], [], []
    for k, (_, _, nm, pos, vel, eff) in enumerate(msgs):
        col = {j: i for i, j in enumerate(nm)}
        missing = [j for j in joints if j not in col]
        if missing:
            what = "model joints" if any(j in names for j in missing) else "joints of the first message"
            raise DataError(f"{where}, message {k}: field 'name': no {what} {missing} (it names {nm}; "
                            f"model joints {names})")
        if eff.size == 0:
            raise DataError(f"{where}, message {k}: field 'effort': empty (a {spec.kind} data set needs the joint "
                            "torques, or motor currents with a scale)")
        for field, arr in (("position", pos), ("effort", eff)) + ((("velocity", vel),) if rates else ()):
            if arr.size != len(nm):
                raise DataError(f"{where}, message {k}: field '{field}': {arr.size} values for {len(nm)} names")
        idx = [col[j] for j in joints]
        q.append(pos[idx])
        tau.append(eff[idx[:len(names)]] * np.array([scale.get(j, 1.0) for j in names]))
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
    arrays = {"q": np.asarray(q)[order], "tau": np.asarray(tau)[order]}
    if rates:
        arrays["qd"] = np.asarray(qd)[order]
    t, arrays = _uniform(t, arrays, where)
    if spec.kind == "response":
        return {"t": t, "tau": arrays["tau"], "y": arrays["q"], "channels": np.asarray(names)}
    return {"t": t, **arrays, "joints": np.asarray(joints)}
