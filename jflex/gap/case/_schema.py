"""The schema of ``case.yaml`` (pydantic): every key, its type and range, which keys each effect
and each data-set format takes. :func:`jflex.gap.load_case` validates with it; what needs the
robot (joint names, frames) or the data files is checked there. ``python -m jflex.gap.case._schema``
prints the table of ``docs/case_format.md``."""

from __future__ import annotations

import math
import pathlib
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationInfo, field_validator, model_validator
from pydantic_core import PydanticCustomError

from ..._schema import Strict, markdown_table
from ..frequency._kinds import frequency_kinds
from ..torque._terms import KINDS as TORQUE_KINDS
from ...effects._registry import JOINT_FLEXIBILITY, ROTOR_INERTIA, SENSOR_DELAY

KINDS = ("torque", "frf", "modal", "response")
SPLITS = ("train", "validation")

# Every candidate name of the library, as its candidate kinds name themselves (the torque side's
# and the frequency side's, the damping laws of jflex.effects among them); nominal effects are
# named from the same list.
EFFECT_NAMES = tuple(dict.fromkeys([*TORQUE_KINDS, *frequency_kinds()]))
# nominal values an effect may state (every other coefficient is fitted)
EFFECT_VALUES = {JOINT_FLEXIBILITY: ("stiffness", "damping"), SENSOR_DELAY: ("value",), ROTOR_INERTIA: ("value",)}

# data file formats by suffix (a ROS 2 bag may also be a folder holding metadata.yaml, see
# file_format); which kinds each carries
FORMATS = {".npz": "npz", ".csv": "csv", ".uff": "uff", ".unv": "uff", ".mcap": "rosbag"}
FORMAT_KINDS = {"npz": KINDS, "csv": ("torque", "response", "modal"), "uff": ("frf",), "rosbag": ("torque", "response")}
# CSV column map: the keys each kind needs and may take (a per-joint key maps joint -> column)
CSV_COLUMNS = {
    "torque": (("time", "position", "torque"), ("velocity", "acceleration")),
    "response": (("time", "torque", "output"), ()),
    "modal": (("frequency", "damping_ratio"), ()),
}
_FORMAT_LABEL = {"npz": ".npz", "csv": ".csv", "uff": ".uff/.unv (UFF58)", "rosbag": "ROS 2 bag (.mcap or bag folder)"}


def file_format(file: str, folder: pathlib.Path | None = None) -> str | None:
    """The format of the data ``file`` a case names: by its suffix, else ``rosbag`` for a folder
    holding ``metadata.yaml`` (a ROS 2 bag) below ``folder``, the case folder; None if neither."""
    fmt = FORMATS.get(pathlib.PurePath(file).suffix.lower())
    if fmt is None and folder is not None and (pathlib.Path(folder) / file / "metadata.yaml").is_file():
        return "rosbag"
    return fmt
FRF_QUANTITIES = ("receptance", "mobility", "accelerance")


def _bad(error_type: str, msg: str, at: str | None = None, **ctx):
    # "at": a key below the checked field, appended to the field path of the error message
    return PydanticCustomError(error_type, msg, {"at": at, **ctx})


def _number(v, rule: str, got) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise _bad("number", "expected a finite number {rule}, got {got}", rule=rule, got=repr(got))
    if (rule == "> 0" and v <= 0) or (rule == ">= 0" and v < 0) or (rule == "!= 0" and v == 0):
        raise _bad("number", "expected a finite number {rule}, got {got}", rule=rule, got=repr(got))
    return float(v)


class NominalEffect(Strict):
    """An effect the nominal model already contains."""

    effect: Literal[EFFECT_NAMES] = Field(description="effect name (the candidates' list)")
    joint: str | int | list[str | int] = Field(
        "all", description="a joint name, a list of names, an index or `all`",
        json_schema_extra={"expects": "joint name, index, list of them, or `all`"})
    stiffness: list[float] | None = Field(
        None, description="`joint_flexibility` only: stiffness [N m/rad] per joint (the start of the refit)",
        json_schema_extra={"expects": "number > 0 or one per joint"})
    damping: list[float] | None = Field(
        None, description="`joint_flexibility` only: damping [N m s/rad] per joint",
        json_schema_extra={"expects": "number >= 0 or one per joint"})
    value: list[float] | None = Field(
        None, description="`sensor_delay` [s] or `rotor_inertia` [kg m^2] (reflected rotor inertia) only",
        json_schema_extra={"expects": "number >= 0 or one per joint"})

    @model_validator(mode="before")
    @classmethod
    def _keys_of_effect(cls, data: Any):
        if isinstance(data, dict) and data.get("effect") in EFFECT_NAMES:
            allowed = ("effect", "joint") + EFFECT_VALUES.get(data["effect"], ())
            for k in data:
                if k not in allowed:
                    raise _bad("effect_key", "unknown key {key} for effect {effect}; allowed keys: {allowed}",
                               at=str(k), key=repr(k), effect=repr(data["effect"]), allowed=list(allowed))
        return data

    @field_validator("joint", mode="before")
    @classmethod
    def _joint(cls, v):
        one = lambda j: (isinstance(j, str) and j != "") or (isinstance(j, int) and not isinstance(j, bool) and j >= 0)
        if v is None:
            return "all"
        if one(v) or (isinstance(v, list) and v and all(one(j) for j in v)):
            return v
        raise _bad("joint", "expected a joint name, an index >= 0, a non-empty list of them or 'all', got {got}",
                   got=repr(v))

    @field_validator("stiffness", "damping", "value", mode="before")
    @classmethod
    def _values(cls, v, info):
        if v is None:
            return v
        rule = "> 0" if info.field_name == "stiffness" else ">= 0"
        items = v if isinstance(v, list) and v else [v]
        return [_number(x, rule, v) for x in items]


class Noise(Strict):
    """Noise floors the data cannot show."""

    modal_frequency_pct: Annotated[float, Field(ge=0)] | None = Field(
        None, description="noise floor of modal tables [%] (default 1 %)", json_schema_extra={"expects": "number >= 0"})
    modal_damping_pct: Annotated[float, Field(ge=0)] | None = Field(
        None, description="relative uncertainty of measured damping ratios [%] (default 15 %)",
        json_schema_extra={"expects": "number >= 0"})


class Options(Strict):
    """Settings of the diagnosis."""

    inertia_prior: Annotated[float, Field(ge=0)] = Field(
        1.0, description="weight of the prior toward the CAD inertial parameters in the nominal refit (0: none)")
    refit_inertia: bool = Field(True, description="refit the inertial parameters in the nominal identification")
    filter_cutoff_hz: float | Literal["auto"] = Field(
        "auto", description="low-pass cutoff [Hz] of angle-only torque data, or `auto` (from the motion band)",
        json_schema_extra={"expects": "number > 0 or `auto`"})
    decimate: Annotated[int, Field(ge=1)] = Field(1, description="keep every n-th sample of filtered torque data")
    max_effects: Annotated[int, Field(ge=0)] = Field(3, description="most effects the selection adds")
    keep_channels: list[str] = Field(
        [], description="torque channels (joint names) kept in the gap although the data check found them dead, "
                        "flat, stuck, saturated or few-level", json_schema_extra={"expects": "list of joint names"})
    replace_spikes: bool = Field(
        False, description="replace the spikes found in torque channels by interpolation (else they are only "
                           "counted and reported)")

    @field_validator("filter_cutoff_hz", mode="before")
    @classmethod
    def _cutoff(cls, v):
        return v if v == "auto" else _number(v, "> 0", v)


_PER_JOINT = {"expects": "mapping joint: column"}


class Columns(Strict):
    """Column map of a CSV data set: CSV header names (a per-joint key maps joint -> column)."""

    time: str | None = Field(None, description="time [s, or `units.time`] (torque, response)")
    position: dict[str, str] | None = Field(
        None, description="angle columns (torque); joints the model lacks are kept as posture variables",
        json_schema_extra=_PER_JOINT)
    velocity: dict[str, str] | None = Field(None, description="rate columns (torque, optional)",
                                             json_schema_extra=_PER_JOINT)
    acceleration: dict[str, str] | None = Field(None, description="acceleration columns (torque, optional)",
                                                 json_schema_extra=_PER_JOINT)
    torque: dict[str, str] | None = Field(
        None, description="torque columns [N m] after `scale` (torque, response: every model joint)",
        json_schema_extra=_PER_JOINT)
    output: dict[str, str] | None = Field(
        None, description="measured channels (response): a model joint [rad] or `tip_x`/`tip_y`/`tip_z` [m]",
        json_schema_extra={"expects": "mapping channel: column"})
    frequency: str | None = Field(None, description="natural frequency [Hz] column (modal)")
    damping_ratio: str | None = Field(None, description="damping-ratio column (modal; empty or NaN: not identified)")


class Units(Strict):
    """Units of a CSV data set's columns (after `scale`)."""

    time: Literal["s", "ms", "us", "ns"] = Field("s", description="time column unit")
    position: Literal["rad", "deg"] = Field(
        "rad", description="angles, their rates (per s) and accelerations (per s^2), `q0` and joint outputs")


class Coupling(Strict):
    """A coupled transmission: motors that drive several joints (e.g. a wrist whose motors 5 and 6
    both move joints 5 and 6)."""

    joints: Annotated[list[str], Field(min_length=2)] = Field(
        description="the coupled joints; the torque column of each is its motor's current",
        json_schema_extra={"expects": "list of 2 or more joint names"})
    matrix: list[list[float]] = Field(
        description="K (m x m): motor rates = K x joint rates, rows motors and columns joints in the order of "
                    "`joints`; joint torques = K^T x motor torques", json_schema_extra={"expects": "square list of rows"})
    angles: Literal["joint", "motor"] = Field(
        "joint", description="what the position columns of `joints` read: `joint` angles, or `motor` encoder "
                             "angles (after `scale` and `offset`, in joint-side units: K x the joint angles; the "
                             "joint angles are K^-1 x them)")

    @model_validator(mode="after")
    def _square(self):
        m = len(self.joints)
        if len(set(self.joints)) != m:
            raise _bad("coupling", "joint names must be unique, got {got}", at="joints", got=self.joints)
        if len(self.matrix) != m or any(len(r) != m for r in self.matrix):
            raise _bad("coupling", "expected {m} rows of {m} numbers (one row per motor of {joints}), got {got}",
                       at="matrix", m=m, joints=self.joints, got=self.matrix)
        for r in self.matrix:
            for x in r:
                _number(x, "", x)
        import numpy as np

        if abs(np.linalg.det(np.asarray(self.matrix, float))) < 1e-12:
            raise _bad("coupling", "singular (every motor must move the joints independently)", at="matrix")
        return self


TODO = "TODO"


def _factors(v, what: str, rule: str):
    if v is None:
        return v
    if not isinstance(v, dict):
        raise _bad("mapping", "expected a mapping {what}: number, got {got}", what=what, got=repr(v))
    for k, x in v.items():
        if not isinstance(k, str):
            raise _bad("mapping", "expected {what} names as keys, got {got}", what=what, got=repr(k))
        if isinstance(x, str) and x.strip().upper().startswith(TODO):
            raise _bad("todo", "not filled in ({got}): state the number (for a motor current column: torque "
                       "constant [N m/A] x gear ratio, from the motor and gear data sheets)", at=k, got=repr(x))
        try:
            _number(x, rule, x)
        except PydanticCustomError:
            raise _bad("mapping", "expected a finite number {rule}, got {got}", at=k, rule=rule, got=repr(x)) from None
    return {k: float(x) for k, x in v.items()}


class Dataset(Strict):
    """One measured data set."""

    kind: Literal[KINDS] = Field(description="what the file holds")
    file: Annotated[str, Field(min_length=1)] | Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)] = Field(
        description="`.npz`, `.csv` (torque, response, modal), `.uff`/`.unv` (frf) or a ROS 2 bag (`.mcap` or a bag "
                    "folder; torque, response) inside the case folder; or a list of CSV files of one run (e.g. "
                    "positions, velocities, efforts), each with the time column, merged on time",
        json_schema_extra={"expects": "file name or list of CSV file names"})
    split: Literal[SPLITS] = Field(description="`train`: fitted; `validation`: the gap is judged on it")
    name: Annotated[str, Field(min_length=1)] | None = Field(None, description="unique name (default: the file's stem)")
    columns: Columns | None = Field(None, description="CSV only: the column map (required for a CSV file)")
    scale: dict[str, float] | None = Field(
        None, description="CSV: column -> factor applied to the raw column (e.g. current [A] x torque constant x "
                          "gear ratio); ROS 2 bag: joint -> factor applied to its `effort`",
        json_schema_extra={"expects": "mapping column (or joint): number != 0"})
    offset: dict[str, float] | None = Field(
        None, description="CSV: column -> raw value subtracted before `scale` (a current offset i0); ROS 2 bag: joint "
                          "-> offset of its `effort`", json_schema_extra={"expects": "mapping column (or joint): number"})
    coupling: Coupling | None = Field(
        None, description="CSV and ROS 2 bag: a coupled transmission; torques = K^T (scale (raw - offset)) "
                          "(+ `torque_offset`)")
    torque_offset: dict[str, float] | None = Field(
        None, description="CSV and ROS 2 bag: joint -> torque [N m] added after scale and coupling (e.g. a "
                          "gravity-compensation spring or a sensor bias)", json_schema_extra={"expects": "mapping joint: number"})
    units: Units | None = Field(None, description="CSV only: units of the time and angle columns")
    window: list[float | None] | None = Field(
        None, description="torque and response sets: the part of the record used, `[start, end]` in seconds from its "
                          "first stamp (`end` null: to the end); one log can then give a train and a validation set",
        json_schema_extra={"expects": "[start, end] seconds, 0 <= start < end"})
    rate: float | None = Field(
        None, description="CSV torque and response logs without a time column only: their sample rate [Hz] (row k "
                          "is at k / rate s); not with `columns.time`", json_schema_extra={"expects": "number > 0"})
    delimiter: Literal[",", ";", "tab", "space"] | None = Field(
        None, description="CSV only: field separator (default: sniffed from the header line)")
    q0: list[float] | dict[str, float] | None = Field(
        None, description="CSV response/modal and UFF frf: the posture, a list in model joint order or joint: angle "
                          "[rad, or `units.position`]", json_schema_extra={"expects": "list of numbers or mapping joint: number"})
    quantity: Literal[FRF_QUANTITIES] | None = Field(
        None, description="UFF only: what the records hold (default: read off their unit labels m, m/s, m/s^2)")
    topic: Annotated[str, Field(min_length=1)] | None = Field(
        None, description="ROS 2 bag only: the `sensor_msgs/msg/JointState` topic (default `/joint_states`)")

    @field_validator("scale", mode="before")
    @classmethod
    def _scale(cls, v):
        return _factors(v, "column", "!= 0")

    @field_validator("offset", "torque_offset", mode="before")
    @classmethod
    def _offsets(cls, v):
        return _factors(v, "key", "")

    @field_validator("window", mode="before")
    @classmethod
    def _window(cls, v):
        if v is None:
            return v
        if not (isinstance(v, list) and len(v) == 2):
            raise _bad("window", "expected [start, end] in seconds from the record's first stamp, got {got}", got=repr(v))
        a = _number(v[0], "", v)
        b = None if v[1] is None else _number(v[1], "", v)
        if not (math.isfinite(a) and a >= 0 and (b is None or (math.isfinite(b) and b > a))):
            raise _bad("window", "expected finite 0 <= start < end (seconds), got {got}", got=repr(v))
        return [a, b]

    @field_validator("rate", mode="before")
    @classmethod
    def _rate(cls, v):
        return None if v is None else _number(v, "> 0", v)

    @field_validator("q0", mode="before")
    @classmethod
    def _q0(cls, v):
        if v is None:
            return v
        if isinstance(v, list) and v:
            return [_number(x, "", v) for x in v]
        if isinstance(v, dict) and v and all(isinstance(k, str) for k in v):
            return {k: _number(x, "", v) for k, x in v.items()}
        raise _bad("q0", "expected a list of numbers [rad] (model joint order) or a mapping joint: angle, got {got}",
                   got=repr(v))

    @model_validator(mode="after")
    def _format_keys(self, info: ValidationInfo):
        files = self.file if isinstance(self.file, list) else [self.file]
        fmts = {file_format(f, (info.context or {}).get("folder")) for f in files}
        if len(files) > 1 and fmts != {"csv"}:
            raise _bad("file", "a list of files is for CSV logs of one run merged on time, got {got}", at="file",
                       got=files)
        fmt = fmts.pop()
        if fmt is None:
            raise _bad("file", "expected a .npz, .csv (torque, response, modal), .uff/.unv (frf) file or a ROS 2 bag "
                       "(.mcap, or a folder holding metadata.yaml; torque, response), got {got}",
                       at="file", got=repr(self.file))
        if self.kind not in FORMAT_KINDS[fmt]:
            ok = " or ".join(_FORMAT_LABEL[f] for f, ks in FORMAT_KINDS.items() if self.kind in ks)
            raise _bad("file", "a {kind} data set cannot be a {fmt} file (expected {ok})", at="file", kind=self.kind,
                       fmt=fmt.upper(), ok=ok)
        csv_only = ("columns", "units", "delimiter", "rate")
        for k in csv_only:
            if fmt != "csv" and getattr(self, k) is not None:
                raise _bad("format_key", "only for CSV data sets (this file is {fmt})", at=k, fmt=fmt.upper())
        for k in ("scale", "offset", "coupling", "torque_offset"):
            if getattr(self, k) is not None and fmt not in ("csv", "rosbag"):
                raise _bad("format_key", "only for CSV data sets and ROS 2 bags (this file is {fmt})", at=k,
                           fmt=fmt.upper())
        if self.topic is not None and fmt != "rosbag":
            raise _bad("format_key", "only for ROS 2 bags (this file is {fmt})", at="topic", fmt=fmt.upper())
        if self.quantity is not None and fmt != "uff":
            raise _bad("format_key", "only for UFF data sets", at="quantity")
        if self.window is not None and self.kind not in ("torque", "response"):
            raise _bad("window", "a time window is for torque and response records, not a {kind} set", at="window",
                       kind=self.kind)
        needs_q0 = fmt == "uff" or (fmt == "csv" and self.kind == "modal")
        if needs_q0 and self.q0 is None:
            raise _bad("missing", "missing (the measurement posture: a {kind} {fmt} file does not hold it)", at="q0",
                       kind=self.kind, fmt=fmt.upper())
        if fmt == "npz" and self.q0 is not None:
            raise _bad("format_key", "not for NPZ data sets (an NPZ file holds its own q0)", at="q0")
        if fmt == "csv":
            if self.columns is None:
                raise _bad("missing", "missing (a CSV data set needs its column map, see docs/case_format.md)",
                           at="columns")
            need, opt = CSV_COLUMNS[self.kind]
            if self.rate is not None:
                if self.kind == "modal":
                    raise _bad("format_key", "a modal table has no time axis (rate is for torque and response "
                               "logs)", at="rate")
                if self.columns.time is not None:
                    raise _bad("format_key", "give the stamps once: either columns.time or rate (a log without a "
                               "time column), not both", at="rate")
                need, opt = tuple(k for k in need if k != "time"), opt
            for k in need:
                if getattr(self.columns, k) is None:
                    raise _bad("missing", "missing (a {kind} CSV needs columns {need})", at=f"columns.{k}",
                               kind=self.kind, need=list(need))
            for k in Columns.model_fields:
                if getattr(self.columns, k) is not None and k not in need + opt:
                    raise _bad("format_key", "not a column of a {kind} data set (needs {need}, may have {opt})",
                               at=f"columns.{k}", kind=self.kind, need=list(need), opt=list(opt))
            if self.kind == "modal" and self.units is not None and self.units.time != "s":
                raise _bad("format_key", "a modal table has no time column", at="units.time")
        return self


class RobotSpec(Strict):
    """The nominal robot with a reduction: the joints the logs drive, the others locked."""

    file: Annotated[str, Field(min_length=1)] = Field(
        description="a URDF or robot YAML (with `urdf:`) inside the case folder, or a config name such as `panda`")
    joints: Annotated[list[Annotated[str, Field(min_length=1)]], Field(min_length=1)] | None = Field(
        None, description="the joints kept (every other moving joint locked at its `lock` value, or 0)",
        json_schema_extra={"expects": "list of joint names"})
    lock: dict[str, float] | None = Field(
        None, description="joint -> value [rad or m] at which it is locked", json_schema_extra={"expects": "mapping joint: number"})

    @field_validator("joints")
    @classmethod
    def _unique(cls, v):
        if v is not None and len(set(v)) != len(v):
            raise _bad("joints", "joint names must be unique, got {got}", got=v)
        return v

    @field_validator("lock", mode="before")
    @classmethod
    def _lock(cls, v):
        return _factors(v, "joint", "")


class CaseSpec(Strict):
    """case.yaml."""

    robot: Annotated[str, Field(min_length=1)] | RobotSpec = Field(
        description="the nominal model: a URDF or robot YAML inside the case folder, or a config name such as `panda`; "
                    "or a mapping `{file, joints, lock}` reducing it to the joints the logs drive",
        json_schema_extra={"expects": "file or config name, or mapping"})
    robot_inertia: Annotated[str, Field(min_length=1)] | None = Field(
        None, description="NPZ with `inertia` (n, 10): link parameters replacing the robot's")
    tool_frame: Annotated[str, Field(min_length=1)] | None = Field(
        None, description="frame of the tool FRFs and tip channels (required with frf data or tip channels)")
    nominal_effects: list[NominalEffect] = Field([], description="what the nominal model already contains")
    datasets: Annotated[list[Dataset], Field(min_length=1)] = Field(
        description="the measured data sets (at least one train and one validation)")
    noise: Noise = Field(Noise(), description="noise floors")
    options: Options = Field(Options(), description="diagnosis settings")
    name: str | None = Field(None, description="the case's name")
    notes: str | None = Field(None, description="free text")

    @field_validator("nominal_effects", "noise", "options", mode="before")
    @classmethod
    def _empty(cls, v, info):
        # an empty YAML block (`noise:`) reads as null: the defaults
        if v is None:
            return [] if info.field_name == "nominal_effects" else {}
        return v


def schema_table() -> str:
    """The markdown table of case.yaml's fields (``docs/case_format.md`` holds it verbatim)."""
    return markdown_table(CaseSpec)


if __name__ == "__main__":
    print(schema_table())
