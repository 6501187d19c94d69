"""``jflex case init ROBOT LOG.csv``: a starting case.yaml from the robot's joint names and a
log's CSV header. Columns are matched by name where they can be (time; per joint its position,
velocity and torque or motor current); whatever is not found is left as a ``TODO`` placeholder,
which :func:`jflex.gap.load_case` refuses by field until it is filled in."""

from __future__ import annotations

import collections
import pathlib
import re
import shutil

import numpy as np
import yaml

from ..._config import load_robot
from ..._errors import ConfigError
from ..._runs import load_yaml
from ...data._csv import Table
from ...effects._registry import COULOMB_FRICTION, VISCOUS_FRICTION

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
    count = collections.Counter(header)
    for col in header:
        words = [w for w in _words(col) if not w.isdigit()]
        if out["time"] is None and any(w in TIME_WORDS for w in words) and _joint_of(col, joints) is None:
            out["time"] = col
            if "ms" in words:
                out["units"]["time"] = "ms"
            continue
        role = next((r for r, ws in ROLE_WORDS.items() if any(w in ws for w in words)), None)
        j = _joint_of(col, joints)
        if role is None and j is not None and _flat(col) == _flat(j) and count[col] == 1:
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


NOMINAL_FRICTION = [{"effect": VISCOUS_FRICTION, "joint": "all"}, {"effect": COULOMB_FRICTION, "joint": "all"}]


class _Dumper(yaml.SafeDumper):
    """A YAML writer without anchors: the training and validation sets share one column map in
    memory, and ``&id001`` / ``*id001`` would make an edit of one silently edit the other."""

    def ignore_aliases(self, data):
        return True


def _stamps(tb, time_col, time_unit, rate):
    """The stamps [s] of the table ``tb``: its time column, or row k at k / ``rate``."""
    if time_col is None:
        return np.arange(len(tb.rows)) / rate
    tt = tb.column(time_col) * {"ms": 1e-3, "us": 1e-6, "ns": 1e-9}.get(time_unit, 1.0)
    return tt[np.isfinite(tt)]


def _split(tt, hold_out, name) -> float:
    """The training window's end [s from the first stamp] that holds out the last ``hold_out`` of the
    record ``tt``; refused by the rule load_case applies to a window (it keeps at least
    ``MIN_WINDOW_SAMPLES`` samples), so a case init writes is not refused when it is loaded."""
    from ._case import MIN_WINDOW_SAMPLES, window_mask

    span = float(tt.max() - tt.min())
    split_s = float(round((1.0 - float(hold_out)) * span, 6))
    kept = {w: int(window_mask(tt, win).sum()) for w, win in (("training", [0.0, split_s]),
                                                                   ("validation", [split_s, None]))}
    short = {w: k for w, k in kept.items() if k < MIN_WINDOW_SAMPLES}
    if short:
        lo = (MIN_WINDOW_SAMPLES - 1) / max(tt.size - 1, 1)
        raise ConfigError(
            f"field 'hold_out': {hold_out:g} leaves " + " and ".join(f"{k} samples for {w}" for w, k in short.items())
            + f" in {name} ({tt.size} samples over {span:.4g} s): expected a fraction that keeps at least "
            f"{MIN_WINDOW_SAMPLES} samples on each side (about {lo:.2g} to {1 - lo:.2g} here)")
    return split_s


def _checked_arguments(log, out, hold_out, rate) -> tuple[list[pathlib.Path], pathlib.Path, pathlib.Path]:
    """The logs, the case folder and its case.yaml, after refusing what case_init cannot use
    (before anything is read or written)."""
    logs = [pathlib.Path(p) for p in (log if isinstance(log, (list, tuple)) else [log])]
    if not logs:
        raise ConfigError("field 'log': no CSV log given")
    if hold_out is not None:
        h = hold_out
        if isinstance(h, bool) or not isinstance(h, (int, float)) or not 0.0 < float(h) < 1.0:
            raise ConfigError(f"field 'hold_out': expected a fraction in (0, 1) (the part of the log held out for "
                              f"validation), got {hold_out!r}")
    if rate is not None and (isinstance(rate, bool) or not isinstance(rate, (int, float)) or not np.isfinite(rate)
                             or rate <= 0):
        raise ConfigError(f"field 'rate': expected a sample rate > 0 [Hz], got {rate!r}")
    folder = pathlib.Path(out) if out is not None else logs[0].parent
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{folder}: field 'out': exists and is not a folder (expected the case folder to write "
                          "case.yaml into, new or existing)")
    target = folder / "case.yaml"
    if target.exists():
        raise ConfigError(f"{target}: exists already (jflex case init does not overwrite a case)")
    return logs, folder, target


def _read_logs(logs, joints, hold_out, rate):
    """The logs' tables, whether they are separate runs (one header) rather than files of one run,
    the header the columns are guessed from, the guess (:func:`guess_columns`), and each data
    set's training end [s] when ``hold_out`` splits them (checked before anything is written)."""
    tables = [Table(p) for p in logs]
    runs = len(tables) > 1 and all(tb.header == tables[0].header for tb in tables)
    header = list(tables[0].header) if runs else [h for tb in tables for h in tb.header]
    g = guess_columns(header, joints)
    if rate is not None and g["time"] is not None:
        raise ConfigError(f"field 'rate': the log has a time column ({g['time']!r}); rate is for logs without one")
    if len(tables) > 1 and not runs and g["time"] is not None:
        lacking = [p.name for p, tb in zip(logs, tables) if g["time"] not in tb.header]
        if lacking:
            raise ConfigError(f"field 'log': the time column {g['time']!r} is not in {lacking}: logs merged on "
                              "time each hold it")
    if hold_out is not None and g["time"] is None and rate is None:
        raise ConfigError("field 'hold_out': needs the time column, which could not be guessed (or the sample "
                          "rate: --rate HZ)")
    # each log's split, checked before anything is written
    splits = None if hold_out is None else [
        min(_split(_stamps(tb, g["time"], g["units"].get("time", "s"), rate), float(hold_out), tb.path.name)
            for tb in group)
        for group in ([[tb] for tb in tables] if runs else
                      [[tb for tb in tables if g["time"] is None or g["time"] in tb.header]])]
    return runs, header, g, splits


def _column_map(g, joints, rate, todo: list) -> dict:
    """The data sets' column map: the guessed columns, a ``TODO`` placeholder (noted in ``todo``)
    for each one not found."""

    def per_joint(role, what):
        m = {}
        for j in joints:
            m[j] = g[role].get(j, f"{TODO}: column of {j} {what}")
            if j not in g[role]:
                todo.append(f"columns.{role}.{j}")
        return m

    columns = {"position": per_joint("position", "angle"), "torque": per_joint("torque", "torque or motor current")}
    if rate is None:
        columns = {"time": g["time"] or f"{TODO}: time column (or give the sample rate: rate: HZ)", **columns}
        if g["time"] is None:
            todo.append("columns.time (or rate: the sample rate [Hz] of a log without a time column; --rate)")
    if all(j in g["velocity"] for j in joints):
        columns["velocity"] = {j: g["velocity"][j] for j in joints}
    return columns


def _datasets(entry, logs, files, runs, hold_out, splits) -> list[dict]:
    """The data sets of ``entry`` (one torque data set's fields): one per run, or each log split by
    ``hold_out`` into training and validation windows; the last run validates otherwise."""
    if runs:
        names = [p.stem for p in logs]
        if len(set(names)) != len(names):
            names = [f"run{k + 1}" for k in range(len(logs))]
        per_file = [dict(entry, file=f, name=nm) for f, nm in zip(files, names)]
    else:
        per_file = [entry]
    if hold_out is not None:
        datasets = []
        for e, split_s in zip(per_file, splits):
            base = e.get("name")
            datasets += [dict(e, name=f"{base}_train" if base else "train", window=[0.0, split_s]),
                         dict(e, split="validation", name=f"{base}_validation" if base else "validation",
                              window=[split_s, None])]
    elif runs:
        datasets = per_file[:-1] + [dict(per_file[-1], split="validation")]
    else:
        datasets = per_file
    return datasets


def _head(logs, files, all_joints, header, reduced, rate, hold_out, runs, todo, datasets) -> list[str]:
    """The comment lines at the top of the case.yaml: what was guessed, and what is left to fill in."""
    validation_note = (
        [f"# The last {100 * float(hold_out):g} % of each log is its validation set (window, seconds from its first "
         "stamp)."] if hold_out is not None else
        [f"# {files[-1]} is the validation set (the gap is judged on it), the other runs the training sets."]
        if runs else
        ["#   - a validation data set: another log with split: validation (the gap is judged on held-out data), "
         "or run 'jflex case init' with --hold-out"])
    return [
        f"# case.yaml written by 'jflex case init' for {', '.join(p.name for p in logs)} (format: docs/case_format.md).",
        f"# Robot joints: {all_joints}; CSV columns: {header}.",
        *([f"# The logs drive {reduced}: the robot is reduced to them (the others locked at 0; add "
           "robot.lock to lock them elsewhere)."] if reduced else []),
        *([f"# No time column: the rows are {float(rate):g} Hz apart (rate)."] if rate is not None else []),
        "# nominal_effects: viscous and Coulomb friction at every joint, fitted on the training data (a real joint",
        "# has both; without them the candidates, one effect at one joint at a time, are left to explain all of",
        "# it). Delete an entry the drives compensate, add what else the model already contains.",
        "# Check the guessed column map and units" + (("; fill in every TODO:") if todo or hold_out is None and not runs
                                                      else "."),
        *[f"#   - datasets[{0 if len(datasets) == 1 else '*'}].{t}" for t in dict.fromkeys(todo)],
        *validation_note,
    ]


def case_init(robot: str, log, out: str | pathlib.Path | None = None, hold_out: float | None = None,
              rate: float | None = None) -> pathlib.Path:
    """Write ``case.yaml`` for the CSV ``log`` (or a list of CSV logs) and the robot ``robot`` (a
    URDF / robot YAML file or a config name) into ``out`` (default: the first log's folder),
    copying the logs and every file the robot needs there when they lie elsewhere (a robot YAML
    and the URDF it names). Several logs with different headers are files of one run (positions,
    velocities, efforts, each with the time column), merged on time by the loader; several logs
    with the same header are separate runs, each its own data set (the last one the validation
    set unless ``hold_out`` splits each). When the logs drive only some of a URDF robot's joints,
    the case reduces the robot to them (``robot: {file, joints}``). A motor-current column gets
    ``scale: TODO``, which :func:`jflex.gap.load_case` refuses until the torque constant is filled
    in. The nominal model gets viscous and Coulomb friction at every joint (``nominal_effects``,
    fitted on the training data): a real joint has both, and without them the friction of every
    joint at once is left to the candidates, which name one effect at one joint at a time. Refuses
    to overwrite a case.yaml.

    ``hold_out``: a fraction in (0, 1): each log's last ``hold_out`` of its duration becomes the
    validation set and the rest the training set (two data sets on the same files with a time
    ``window`` each), so a single run gives a complete case; default: one training set, and the
    case names the validation set it still needs. Each window must keep at least 20 samples, as
    :func:`jflex.gap.load_case` requires.

    ``rate``: the sample rate [Hz] of logs without a time column (row k at k / rate s).

    **Returns:** the path of the written case.yaml.
    """
    logs, folder, target = _checked_arguments(log, out, hold_out, rate)
    rob = load_robot(robot)
    joints = list(rob.joint_names)
    runs, header, g, splits = _read_logs(logs, joints, hold_out, rate)
    folder.mkdir(parents=True, exist_ok=True)

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
    columns = _column_map(g, joints, rate, todo)
    files = [local(p) for p in logs]
    entry = {"kind": "torque", "file": files[0] if len(files) == 1 else files, "split": "train", "columns": columns}
    if rate is not None:
        entry["rate"] = float(rate)
    currents = [c for c in g["current"] if c in columns["torque"].values()]
    if currents:
        entry["scale"] = {c: f"{TODO}: torque constant [N m/A] x gear ratio" for c in currents}
        todo.append("scale (torque constant [N m/A] x gear ratio of each motor current column; the case is refused "
                    "until it is filled in)")
    entry["units"] = {"time": g["units"].get("time", "s"), "position": g["units"].get("position", "rad")}
    datasets = _datasets(entry, logs, files, runs, hold_out, splits)
    cfg = {"robot": {"file": robot_entry, "joints": reduced} if reduced else robot_entry,
           "nominal_effects": [dict(e) for e in NOMINAL_FRICTION], "datasets": datasets}
    head = _head(logs, files, list(rob.joint_names), header, reduced, rate, hold_out, runs, todo, datasets)
    target.write_text("\n".join(head) + "\n" + yaml.dump(cfg, Dumper=_Dumper, sort_keys=False))
    return target
