"""YAML robot configs -> validated :class:`Robot` objects, with errors that name the field.

A robot file (``configs/robots/*.yaml``) holds either a DH table or a URDF reference::

    name: staubli_tx200
    dh:
      convention: modified          # or standard
      columns: [alpha, a, d, theta] # the order of each row (any permutation of these four)
      angles: deg                   # unit of alpha and theta: deg or rad
      rows:
        - [0, 0, 0.642, 0]
        - [90, 0.25, 0, 0]
      joint_types: [revolute, revolute]    # optional, default revolute
      tool: [0, 0.994, 0, 0]               # optional DH row of the tool frame (same columns)
    joint_names: [j1, j2]                  # optional
    limits: {lower: [...], upper: [...], velocity: [...], effort: [...], angles: deg}  # optional
    links:                                 # optional inertials in each link's DH frame
      - {mass: 10.0, com: [0, 0, 0.1], inertia: [Ixx, Ixy, Iyy, Ixz, Iyz, Izz]}
    gravity: [0, 0, -9.81]

or ``urdf: path/to/robot.urdf`` (relative to the YAML file), optionally reduced as in
:func:`load_urdf`: ``lock: {torso_1_joint: 0.1}`` [rad or m] and/or ``joints: [arm_1, arm_2]``
(the joints kept, every other one locked at its ``lock`` value or 0).
"""

from __future__ import annotations

import numbers
import os
import pathlib
from typing import Any

import numpy as np

from ._dh import from_dh
from ._errors import ConfigError, JFlexError
from ._paths import shipped_dirs
from ._robot import Robot
from ._runs import load_yaml
from ._urdf import load_urdf

_COLUMNS = ("alpha", "a", "d", "theta")


def config_dirs() -> list[pathlib.Path]:
    """Folders searched for robot names: ``$JFLEX_CONFIGS/robots``, ``./configs/robots`` and the
    ``configs/robots`` jflex ships (inside the installed package, or in the source checkout)."""
    dirs = []
    if os.environ.get("JFLEX_CONFIGS"):
        dirs.append(pathlib.Path(os.environ["JFLEX_CONFIGS"]) / "robots")
    dirs.append(pathlib.Path.cwd() / "configs" / "robots")
    dirs.extend(d / "robots" for d in shipped_dirs("configs"))
    return dirs


def _example_robot_urdf(name: str) -> pathlib.Path | None:
    rel = {
        "panda": "panda_description/urdf/panda.urdf",
        "ur5": "ur_description/urdf/ur5_robot.urdf",
    }.get(name)
    if rel is None:
        return None
    import importlib.metadata as md

    try:
        files = md.files("example-robot-data") or []
    except md.PackageNotFoundError:
        return None
    for f in files:
        if str(f).replace("\\", "/").endswith("robots/" + rel):
            path = pathlib.Path(f.locate())
            if path.is_file():
                return path
    return None


# The named robot is the 7-joint arm with the hand closed (the fingers, coupled by <mimic>,
# locked), as the benchmarks use it; load_urdf of the shipped file keeps the fingers coupled.
_EXAMPLE_LOCKS = {"panda": {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}}


def available_robots() -> list[str]:
    """Names accepted by :func:`load_robot` besides paths."""
    names = set()
    for d in config_dirs():
        if d.is_dir():
            names.update(p.stem for p in d.glob("*.yaml"))
    for extra in ("panda", "ur5"):
        if _example_robot_urdf(extra) is not None:
            names.add(extra)
    return sorted(names)


# the most a file name and a path may hold on the usual file systems (NAME_MAX, PATH_MAX): a
# longer one is refused by name here instead of an OSError from the first stat
_NAME_MAX, _PATH_MAX = 255, 4096


def _checked_spec(s: str, field: str) -> str:
    """``s`` if it can name a file; else a :class:`ConfigError` naming ``field`` (shortened)."""
    shown = repr(s) if len(s) <= 80 else repr(s[:60]) + f"... ({len(s)} characters)"
    if "\x00" in s:
        raise ConfigError(f"{field}: {shown} contains a NUL byte; expected a robot name or a file path")
    if len(s) > _PATH_MAX or any(len(part) > _NAME_MAX for part in pathlib.PurePath(s).parts):
        raise ConfigError(f"{field}: {shown} is too long for a robot name or a file path "
                          f"(at most {_NAME_MAX} characters a name, {_PATH_MAX} a path)")
    return s


def load_robot(spec: str | os.PathLike | dict, *, within: str | os.PathLike | None = None) -> Robot:
    """A :class:`Robot` from a YAML file, a URDF file, a config name (``"staubli_tx200"``, or
    ``"panda"``/``"ur5"`` when ``example-robot-data`` is installed; ``"panda"`` is the 7-joint arm, its
    fingers locked closed) or an already-parsed mapping.

    ``within``: a folder the files a robot YAML names (its ``urdf:``) must stay inside (a case
    folder: a YAML there must not read ``/etc/passwd`` or ``../other.urdf``); ``None`` lets them
    lie anywhere."""
    if isinstance(spec, dict):
        return robot_from_config(spec, where="<config>", within=within)
    s = _checked_spec(os.fspath(spec) if isinstance(spec, os.PathLike) else str(spec), "robot")
    path = pathlib.Path(s)
    if path.suffix.lower() == ".urdf":
        return load_urdf(path)
    if path.suffix.lower() in (".yaml", ".yml"):
        return robot_from_config(load_yaml(path), where=str(path), base=path.parent, within=within)
    for d in config_dirs():
        cand = d / f"{s}.yaml"
        if cand.is_file():
            return robot_from_config(load_yaml(cand), where=str(cand), base=cand.parent)
    urdf = _example_robot_urdf(s)
    if urdf is not None:
        return load_urdf(urdf, lock=_EXAMPLE_LOCKS.get(s))
    extra = _missing_extra(s)
    if extra:
        raise ConfigError(extra)
    raise ConfigError(f"unknown robot '{s}': not a .yaml/.urdf path, and not one of {available_robots()}")


def _missing_extra(name: str) -> str | None:
    """What to install for a robot name jflex knows but cannot load here (``None``: not one)."""
    if name not in ("panda", "ur5"):
        return None
    try:
        import importlib.metadata as md

        md.distribution("example-robot-data")
    except Exception:  # noqa: BLE001 - any failure to find it means it is not usable here
        return (f"robot '{name}' comes from the example-robot-data package, which is not installed: "
                f'pip install "jflex[robots]" (or pip install example-robot-data)')
    return (f"robot '{name}': example-robot-data is installed but its {name} URDF was not found in it; "
            'reinstall it (pip install --force-reinstall example-robot-data)')


def _numbers(value: Any, where: str, shape=None) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected numbers, got {value!r}") from None
    if shape is not None and arr.shape != shape:
        raise ConfigError(f"{where}: expected shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ConfigError(f"{where}: contains NaN or inf")
    return arr


def _angle_unit(cfg, where, default="rad"):
    unit = cfg.get("angles", default)
    if unit not in ("deg", "rad"):
        raise ConfigError(f"{where}.angles: expected 'deg' or 'rad', got {unit!r}")
    return np.pi / 180.0 if unit == "deg" else 1.0


def robot_from_config(cfg: dict, where: str = "<config>", base: pathlib.Path | None = None,
                      within: str | os.PathLike | None = None) -> Robot:
    """Validate a robot config mapping and build the :class:`Robot` (see module docstring).
    ``base``: the folder relative paths start from; ``within``: a folder every path the config
    names must stay inside (see :func:`load_robot`)."""
    try:
        return _robot_from_config(cfg, where, base, within)
    except JFlexError:
        raise
    except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
        # Anything the explicit checks missed still reaches the user as a config error.
        raise ConfigError(f"{where}: invalid robot config ({type(exc).__name__}: {exc})") from None


def _confined(path: pathlib.Path, given: str, within, field: str) -> pathlib.Path:
    """``path`` if it lies inside ``within`` (symbolic links resolved), else a ConfigError."""
    if within is None:
        return path
    root = pathlib.Path(within).resolve()
    hint = "a robot file inside a case names files inside the case folder (pass allow_outside=True to read it)"
    if pathlib.PurePath(given).is_absolute():
        raise ConfigError(f"{field}: absolute path {given!r} leaves {root}: {hint}")
    if not path.resolve().is_relative_to(root):
        raise ConfigError(f"{field}: {given!r} resolves outside {root}: {hint}")
    return path


def _names(value, field: str) -> list[str] | None:
    """A list of distinct strings (joint names), or a ConfigError naming ``field``."""
    if value is None:
        return None
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise ConfigError(f"{field}: expected a list of joint names (strings), got {value!r}")
    seen = set()
    for v in value:
        if v in seen:
            raise ConfigError(f"{field}: joint {v!r} is listed twice; each joint once")
        seen.add(v)
    return value


# Why this validation is written by hand while case.yaml and the experiment configs use pydantic
# (jflex._schema): nearly every rule here ties one field to another - joint_names, links and each
# limits list must be as long as the DH table has rows, the column order permutes every row and the
# tool row, the angle unit applies to revolute joints only, lock/joints exist only beside urdf -
# so a pydantic model would hold these same lines in model validators, and the inertial checks
# (positive definite, triangle inequality) stay in from_dh/load_urdf, which also serve Python
# callers. Each message names the field as "<file>.dh.rows[1]". Worth moving when the robot file
# needs a generated docs table like case.yaml's (jflex._schema.markdown_table).
def _robot_from_config(cfg, where, base, within=None):
    if not isinstance(cfg, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(cfg).__name__}")
    known = {"name", "source", "notes", "dh", "urdf", "lock", "joints", "joint_names", "limits", "links", "gravity", "units"}
    unknown = set(cfg) - known
    if unknown:
        raise ConfigError(f"{where}: unknown keys {sorted(unknown)}; expected some of {sorted(known)}")
    gravity = _numbers(cfg.get("gravity", [0.0, 0.0, -9.81]), f"{where}.gravity", (3,))
    if ("dh" in cfg) == ("urdf" in cfg):
        raise ConfigError(f"{where}: needs exactly one of 'dh' (a DH table) or 'urdf' (a file path)")
    if "urdf" in cfg:
        if not isinstance(cfg["urdf"], str):
            raise ConfigError(f"{where}.urdf: expected a file path, got {cfg['urdf']!r}")
        given = _checked_spec(cfg["urdf"], f"{where}.urdf")
        path = pathlib.Path(given)
        if not path.is_absolute() and base is not None:
            path = base / path
        path = _confined(path, given, within, f"{where}.urdf")
        joints = _names(cfg.get("joints"), f"{where}.joints")
        return load_urdf(path, gravity=gravity, lock=cfg.get("lock"), joints=joints)
    for key in ("lock", "joints"):
        if key in cfg:
            raise ConfigError(f"{where}.{key}: only a 'urdf' robot can lock joints (a DH table has no fixed joints)")

    dh = cfg["dh"]
    if not isinstance(dh, dict):
        raise ConfigError(f"{where}.dh: expected a mapping with 'rows', got {type(dh).__name__}")
    cols = dh.get("columns", list(_COLUMNS))
    if not isinstance(cols, list) or sorted(map(str, cols)) != sorted(_COLUMNS):
        raise ConfigError(f"{where}.dh.columns: expected a permutation of {list(_COLUMNS)}, got {cols!r}")
    order = [cols.index(c) for c in _COLUMNS]
    rows = dh.get("rows")
    if not isinstance(rows, list) or not rows:
        raise ConfigError(f"{where}.dh.rows: expected a non-empty list of rows [{', '.join(cols)}]")
    for i, row in enumerate(rows):
        if not isinstance(row, list) or len(row) != 4:
            raise ConfigError(
                f"{where}.dh.rows[{i}]: expected 4 columns [{', '.join(map(str, cols))}], got {row!r}"
            )
        for v in row:
            if not isinstance(v, numbers.Real) or isinstance(v, bool):
                raise ConfigError(f"{where}.dh.rows[{i}]: expected numbers, got {row!r}")
    scale = _angle_unit(dh, f"{where}.dh")
    tab = _numbers(rows, f"{where}.dh.rows")[:, order]
    tab[:, [0, 3]] *= scale
    n = tab.shape[0]
    tool = dh.get("tool")
    if tool is not None:
        tool = _numbers(tool, f"{where}.dh.tool", (4,))[order]
        tool[[0, 3]] *= scale
    convention = dh.get("convention", "modified")
    if convention not in ("modified", "standard"):
        raise ConfigError(f"{where}.dh.convention: expected 'modified' (Craig) or 'standard', got {convention!r}")
    jt = dh.get("joint_types")
    if jt is not None and (not isinstance(jt, list) or len(jt) != n):
        raise ConfigError(f"{where}.dh.joint_types: expected a list of {n} entries, got {jt!r}")
    names = cfg.get("joint_names")
    if names is not None and (not isinstance(names, list) or len(names) != n or not all(isinstance(s, str) for s in names)):
        raise ConfigError(f"{where}.joint_names: expected a list of {n} strings, got {names!r}")
    _names(names, f"{where}.joint_names")
    links = cfg.get("links")
    if links is not None:
        if not isinstance(links, list) or len(links) != n:
            raise ConfigError(f"{where}.links: expected a list of {n} link inertials, got {links!r}")
        for i, ln in enumerate(links):
            if not isinstance(ln, dict):
                raise ConfigError(f"{where}.links[{i}]: expected a mapping {{mass, com, inertia}}, got {ln!r}")
            if "params" not in ln and "mass" not in ln:
                raise ConfigError(f"{where}.links[{i}]: needs 'mass' (kg), or 'params' (10 numbers)")
            if "mass" in ln:
                m = _numbers(ln["mass"], f"{where}.links[{i}].mass", ())
                if m < 0:
                    raise ConfigError(f"{where}.links[{i}].mass: must be >= 0 kg, got {float(m)}")
    lim = cfg.get("limits", {}) or {}
    if not isinstance(lim, dict):
        raise ConfigError(f"{where}.limits: expected a mapping, got {lim!r}")
    lscale = _angle_unit(lim, f"{where}.limits")
    types = [str(t).lower() for t in (jt or ["revolute"] * n)]
    ang = np.array([lscale if t in ("revolute", "r") else 1.0 for t in types])

    def lim_arr(key):
        if key not in lim:
            return None
        return _numbers(lim[key], f"{where}.limits.{key}", (n,)) * (ang if key in ("lower", "upper", "velocity") else 1.0)

    try:
        return from_dh(
            tab,
            convention=convention,
            joint_types=jt,
            tool=tool,
            inertias=links,
            gravity=gravity,
            joint_names=names,
            lower=lim_arr("lower"),
            upper=lim_arr("upper"),
            velocity_limit=lim_arr("velocity"),
            effort_limit=lim_arr("effort"),
        )
    except JFlexError as exc:
        raise ConfigError(f"{where}: {exc}") from None
