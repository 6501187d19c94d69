"""``jflex case init ROBOT LOG.csv``: a starting case.yaml from the robot's joint names and a
log's CSV header. Columns are matched by name where they can be (time; per joint its position,
velocity and torque or motor current); whatever is not found is left as a ``TODO`` placeholder,
which :func:`jflex.gap.load_case` refuses by field until it is filled in."""

from __future__ import annotations

import pathlib
import re
import shutil

import numpy as np
import yaml

from .._config import load_robot
from .._errors import ConfigError
from .._runs import load_yaml
from ._csv import Table

TIME_WORDS = ("time", "t", "timestamp", "stamp", "sec", "secs")
# role -> header words that name it (a word is a maximal run of letters)
ROLE_WORDS = {
    "velocity": ("velocity", "vel", "qd", "dq", "speed", "omega", "rate", "dps"),
    "torque": ("torque", "tau", "effort", "trq", "current", "cur", "curr", "i", "amp", "amps"),
    "position": ("position", "pos", "angle", "q", "theta", "enc"),
}
CURRENT_WORDS = ("current", "cur", "curr", "i", "amp", "amps")
TODO = "TODO"


def _words(name: str) -> list[str]:
    return re.findall(r"[a-z]+|\d+", name.lower())


def _flat(name: str) -> str:
    return re.sub(r"[^a-z0-9]", "", name.lower())


def _joint_of(col: str, joints: list[str]) -> str | None:
    """The joint a header names: by its name, else by its number (``q3``: the third joint, or the
    joint whose name ends in 3)."""
    flat = re.sub(r"[^a-z0-9]", "", col.lower())
    by_name = [j for j in joints if re.sub(r"[^a-z0-9]", "", j.lower()) in flat]
    if len(by_name) == 1:
        return by_name[0]
    if len(by_name) > 1:  # 'joint1' in 'joint12': the longest name wins
        return max(by_name, key=len)
    nums = [w for w in _words(col) if w.isdigit()]
    if len(nums) != 1:
        return None
    k = int(nums[0])
    ends = [j for j in joints if re.search(rf"(?<!\d){k}$", j)]
    if len(ends) == 1:
        return ends[0]
    return joints[k - 1] if 1 <= k <= len(joints) else None


def guess_columns(header: list[str], joints: list[str]) -> dict:
    """``{time, position, velocity, torque, current: [columns], units}`` guessed from ``header``."""
    out = {"time": None, "position": {}, "velocity": {}, "torque": {}, "current": [], "units": {}}
    for col in header:
        words = [w for w in _words(col) if not w.isdigit()]
        if out["time"] is None and any(w in TIME_WORDS for w in words) and _joint_of(col, joints) is None:
            out["time"] = col
            if "ms" in words:
                out["units"]["time"] = "ms"
            continue
        role = next((r for r, ws in ROLE_WORDS.items() if any(w in ws for w in words)), None)
        j = _joint_of(col, joints)
        if role is None and j is not None and _flat(col) == _flat(j) and header.count(col) == 1:
            role = "position"  # a bare joint name: a log of angles headed by the joints' names
        if role is None or j is None or j in out[role]:
            continue
        out[role][j] = col
        if role == "torque" and any(w in CURRENT_WORDS for w in words):
            out["current"].append(col)
        if role == "position" and "deg" in words:
            out["units"]["position"] = "deg"
    return out


def _copy_robot(robot: str, folder: pathlib.Path, local) -> str:
    """Copy the robot file into the case folder with every file it needs: a robot YAML's URDF is
    copied beside it and the copy's ``urdf:`` rewritten to it (meshes are not read)."""
    rpath = pathlib.Path(robot)
    suffix = rpath.suffix.lower()
    if suffix == ".urdf":
        return local(rpath)
    if suffix not in (".yaml", ".yml"):
        return str(robot)
    cfg = load_yaml(rpath)
    if isinstance(cfg, dict) and isinstance(cfg.get("urdf"), str):
        urdf = (rpath.parent / cfg["urdf"]).resolve()
        if not urdf.is_file():
            raise ConfigError(f"{rpath}: field 'urdf': {cfg['urdf']} not found (relative to the YAML file)")
        name = local(urdf)
        target = folder / rpath.name
        if target.exists() and target.resolve() != rpath.resolve():
            raise ConfigError(f"{target}: exists already (jflex case init does not overwrite it)")
        if target.resolve() != rpath.resolve() or cfg["urdf"] != name:
            target.write_text(f"# {rpath.name} as 'jflex case init' copied it, its URDF beside it\n"
                              + yaml.safe_dump({**cfg, "urdf": name}, sort_keys=False))
        return rpath.name
    return local(rpath)


def case_init(robot: str, log, out: str | pathlib.Path | None = None, hold_out: float | None = None) -> pathlib.Path:
    """Write ``case.yaml`` for the CSV ``log`` (or a list of CSV logs of one run: positions,
    velocities, efforts, each with the time column, merged on time by the loader) and the robot
    ``robot`` (a URDF / robot YAML file or a config name) into ``out`` (default: the first log's
    folder), copying the logs and every file the robot needs there when they lie elsewhere (a
    robot YAML and the URDF it names). When the logs drive only some of a URDF robot's joints,
    the case reduces the robot to them (``robot: {file, joints}``). A motor-current column gets
    ``scale: TODO``, which :func:`jflex.gap.load_case` refuses until the torque constant is filled
    in. Refuses to overwrite a case.yaml.

    ``hold_out``: a fraction in (0, 1): the log's last ``hold_out`` of its duration becomes the
    validation set and the rest the training set (two data sets on the same files with a time
    ``window`` each), so a single run gives a complete case; default: one training set, and the
    case names the validation set it still needs.

    **Returns:** the path of the written case.yaml.
    """
    logs = [pathlib.Path(p) for p in (log if isinstance(log, (list, tuple)) else [log])]
    if not logs:
        raise ConfigError("jflex case init: no CSV log given")
    folder = pathlib.Path(out) if out is not None else logs[0].parent
    folder.mkdir(parents=True, exist_ok=True)
    target = folder / "case.yaml"
    if target.exists():
        raise ConfigError(f"{target}: exists already (jflex case init does not overwrite a case)")
    rob = load_robot(robot)
    joints = list(rob.joint_names)
    tables = [Table(p) for p in logs]
    header = [h for tb in tables for h in tb.header]
    g = guess_columns(header, joints)
    if len(tables) > 1 and g["time"] is not None:
        lacking = [p.name for p, tb in zip(logs, tables) if g["time"] not in tb.header]
        if lacking:
            raise ConfigError(f"jflex case init: the time column {g['time']!r} is not in {lacking}: logs merged on "
                              "time each hold it")

    def local(p: pathlib.Path) -> str:
        if p.resolve().parent != folder.resolve():
            shutil.copy2(p, folder / p.name)
        return p.name

    robot_entry = _copy_robot(str(robot), folder, local)
    reduced = None
    urdf_robot = pathlib.Path(str(robot)).suffix.lower() in (".urdf", ".yaml", ".yml")
    if urdf_robot and g["position"] and len(g["position"]) < len(joints):
        reduced = [j for j in joints if j in g["position"]]
        joints = reduced
    todo = []

    def per_joint(role, what):
        m = {}
        for j in joints:
            m[j] = g[role].get(j, f"{TODO}: column of {j} {what}")
            if j not in g[role]:
                todo.append(f"columns.{role}.{j}")
        return m

    columns = {"time": g["time"] or f"{TODO}: time column", "position": per_joint("position", "angle"),
               "torque": per_joint("torque", "torque or motor current")}
    if g["time"] is None:
        todo.append("columns.time")
    if all(j in g["velocity"] for j in joints):
        columns["velocity"] = {j: g["velocity"][j] for j in joints}
    files = [local(p) for p in logs]
    entry = {"kind": "torque", "file": files[0] if len(files) == 1 else files, "split": "train", "columns": columns}
    currents = [c for c in g["current"] if c in columns["torque"].values()]
    if currents:
        entry["scale"] = {c: f"{TODO}: torque constant [N m/A] x gear ratio" for c in currents}
        todo.append("scale (torque constant [N m/A] x gear ratio of each motor current column; the case is refused "
                    "until it is filled in)")
    entry["units"] = {"time": g["units"].get("time", "s"), "position": g["units"].get("position", "rad")}
    datasets = [entry]
    if hold_out is not None:
        if not 0.0 < float(hold_out) < 1.0:
            raise ConfigError(f"jflex case init: hold_out must lie in (0, 1) (the fraction of the log held out for "
                              f"validation), got {hold_out}")
        if g["time"] is None:
            raise ConfigError("jflex case init: hold_out needs the time column, which could not be guessed")
        tb = next(tb for tb in tables if g["time"] in tb.header)
        tt = tb.column(g["time"]) * {"ms": 1e-3, "us": 1e-6, "ns": 1e-9}.get(entry["units"]["time"], 1.0)
        tt = tt[np.isfinite(tt)]
        split_s = float(round((1.0 - float(hold_out)) * (tt.max() - tt.min()), 6))
        datasets = [dict(entry, name="train", window=[0.0, split_s]),
                    dict(entry, split="validation", name="validation", window=[split_s, None])]
    cfg = {"robot": {"file": robot_entry, "joints": reduced} if reduced else robot_entry,
           "nominal_effects": [], "datasets": datasets}
    head = [
        f"# case.yaml written by 'jflex case init' for {', '.join(p.name for p in logs)} (format: docs/case_format.md).",
        f"# Robot joints: {list(rob.joint_names)}; CSV columns: {header}.",
        *([f"# The logs drive {reduced}: the robot is reduced to them (the others locked at 0; add "
           "robot.lock to lock them elsewhere)."] if reduced else []),
        "# Check the guessed column map and units; fill in every TODO:",
        *[f"#   - datasets[0].{t}" for t in todo],
        *(["#   - a validation data set: another log with split: validation (the gap is judged on held-out data), "
            "or run 'jflex case init' with --hold-out"] if hold_out is None else
          [f"# The last {100 * float(hold_out):g} % of the log is the validation set (window, seconds from its first stamp)."]),
        "#   - nominal_effects: what the nominal model already contains (e.g. {effect: viscous_friction, joint: all})",
    ]
    target.write_text("\n".join(head) + "\n" + yaml.safe_dump(cfg, sort_keys=False))
    return target
