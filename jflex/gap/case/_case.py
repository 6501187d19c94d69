"""A gap-diagnosis case: a nominal model plus measured data sets, validated before any fit.

A case is a folder with ``case.yaml`` (format in ``docs/case_format.md``). Every mistake a user
can make in it raises :class:`jflex.ConfigError` (the YAML) or :class:`jflex.DataError` (an NPZ
file) naming the file and the field, before anything is fitted.
"""

from __future__ import annotations

import dataclasses
import pathlib
import re
import warnings

import numpy as np

from ..._config import load_robot
from ..._errors import ConfigError, DataError, JFlexError
from ..._runs import load_yaml
from ..._schema import validate
from ...data._condition import BRIDGE, MAX_GAP
from ...data._fields import numeric_field
from ...data._log_map import LogMap
from ...data._frf_checks import frf_arrays, modal_arrays
from ...data._npz import NPZ_KEYS, load_npz_fields
from ...data._posture import yaml_posture as yaml_posture
from ...data._response import TIP_CHANNELS, response_arrays, uniform_response
from ...data._torque_fields import MIN_WINDOW_SAMPLES, torque_arrays
from ...data._window import window_mask, window_rows
from ._schema import EFFECT_NAMES, EFFECT_VALUES, KINDS, SPLITS, CaseSpec, RobotSpec, file_format
from ...effects._registry import JOINT_FLEXIBILITY, SENSOR_DELAY

__all__ = ["Case", "Dataset", "load_case", "case_path", "EFFECT_NAMES", "KINDS", "SPLITS"]


@dataclasses.dataclass
class Dataset:
    """One measured data set of a case, arrays in SI units.

    ``arrays`` holds the NPZ fields; for torque data ``q`` is reordered to the model's joints and
    ``q_extra`` / ``extra_joints`` keep the columns of joints the model leaves out. For FRF and
    modal data ``q0`` likewise becomes the model posture and ``q0_extra`` the rest.

    ``conditioning`` is what the data layer did to the samples (:mod:`jflex.data`: stamps made
    uniform, channels checked, spikes counted; for the report); ``excluded_channels`` the model
    joints whose torque channel it found dead, flat, stuck, saturated or few-level and that the
    case does not keep (``options.keep_channels``): the gap leaves them out. ``channels`` holds
    the per-channel metadata (:class:`jflex.data.Channel`), ``files`` every file read.

    A torque log with gaps too long to bridge gives one data set per stretch between them, named
    ``<name>#k`` (k counting the stretches in time order), each with the log's split, file and
    settings; ``conditioning["sampling"]["split_from"]`` says which stretch it is and lists the gaps.
    """

    kind: str
    file: pathlib.Path
    split: str
    name: str
    arrays: dict
    extra_joints: tuple[str, ...] = ()
    conditioning: dict = dataclasses.field(default_factory=dict)
    excluded_channels: tuple[str, ...] = ()
    channels: dict = dataclasses.field(default_factory=dict)
    files: tuple = ()


@dataclasses.dataclass
class Case:
    """A validated case: nominal robot, tool frame, nominal effects and data sets."""

    path: pathlib.Path
    robot: object
    tool_frame: str | None
    nominal_effects: list
    datasets: list
    noise: dict
    options: dict
    warnings: list = dataclasses.field(default_factory=list)

    def split(self, split: str, kind: str | None = None) -> list[Dataset]:
        """The data sets of ``split`` (``train``/``validation``), of ``kind`` if given."""
        return [d for d in self.datasets if d.split == split and (kind is None or d.kind == kind)]

    @property
    def excluded_channels(self) -> tuple[str, ...]:
        """Model joints whose torque channel some data set left out, in model order."""
        bad = {j for d in self.datasets for j in d.excluded_channels}
        return tuple(j for j in self.robot.joint_names if j in bad)


def _err(file, field, msg):
    return ConfigError(f"{file}: field '{field}': {msg}")


def _resolve_joints(spec, robot, file, field) -> tuple[str, ...]:
    names = tuple(robot.joint_names)
    if spec is None or spec == "all":
        return names
    items = [spec] if isinstance(spec, (str, int)) else list(spec)
    if "all" in items:
        raise _err(file, field, "'all' stands alone, not in a list")
    out = []
    for j in items:
        if isinstance(j, int) and not isinstance(j, bool):
            if not 0 <= j < len(names):
                raise _err(file, field, f"joint index {j} out of range; the model has joints {list(names)}")
            out.append(names[j])
        elif isinstance(j, str) and j in names:
            out.append(j)
        else:
            raise _err(file, field, f"unknown joint {j!r}; the model has joints {list(names)} (or 'all')")
    return tuple(out)


STRETCH_MARK = "#"  # a stretch of a split log is named <data set>#<k>, k counting its stretches in time order


def _too_short(data, report, options) -> str | None:
    """Why a stretch cut from a log is too short for the diagnosis' processing of it
    (:func:`jflex.gap.torque_set`, with the case's ``filter_cutoff_hz`` and ``decimate``), or None:
    angles low-passed there lose ``EDGE_PERIODS`` periods of the cutoff at each end to the filter's
    transients and keep at least 20 samples per decimation step between them."""
    from ...data._condition import choose_cutoff
    from ...data._angle_log import EDGE_PERIODS
    from ...data._condition import CUTOFF_FACTOR, CUTOFF_LIMIT

    t = data["t"]
    if report.get("derivatives") == "given":  # used as they are, unfiltered
        return None
    k = int(options.get("decimate") or 1)
    h = float(np.mean(np.diff(t)))
    fc = options.get("filter_cutoff_hz")
    if fc in (None, "auto"):
        qd = data["qd"] if report.get("derivatives") == "velocity" else None
        fc, _ = choose_cutoff(data["q"], h, qd=qd, factor=CUTOFF_FACTOR, decimate=k, limit=CUTOFF_LIMIT,
                              resampled=bool((report.get("sampling") or {}).get("resampled")))
    edge = int(np.ceil(EDGE_PERIODS / fc / h))
    if t.size - 2 * edge >= 20 * k:
        return None
    return (f"its low-pass at {fc:.3g} Hz loses {edge * h:.3g} s at each end to its transients, leaving "
            f"{max(t.size - 2 * edge, 0)} of the {20 * k} samples needed")


def _stretches(stretches, split_report, base: str, path, options):
    """The data sets of one torque log (:func:`jflex.data._torque_fields.torque_arrays` with ``split``): ``(kept, notes)``, ``kept``
    a list of ``(name, (arrays, report, excluded), split_from)``. A log conditioned whole keeps its
    name and ``split_from`` None. A log cut at gaps too long to bridge gives one data set per
    stretch, ``base#k`` (k counting every stretch in time order), each with ``split_from`` (the
    record, the stretch, its span and every gap of the log); a stretch too short to be processed
    is dropped. ``notes``: the sentences saying so, for the user and the report."""
    if split_report is None:
        (_, result), = stretches
        return [(base, result, None)], []
    gaps = split_report["gaps"]
    cut = [g for g in gaps if g["action"] == "split"]
    total = len(stretches)
    kept, dropped = [], []
    for k, ((a, b, rows), result) in enumerate(stretches, start=1):
        name = f"{base}{STRETCH_MARK}{k}"
        why = (f"{rows} sample(s), fewer than {MIN_WINDOW_SAMPLES}" if result is None
               else _too_short(*result[:2], options))
        if why is not None:
            dropped.append(f"'{name}' ({a:.6g} to {b:.6g} s, {rows} samples: {why})")
            continue
        split_from = {"record": base, "stretch": k, "stretches": total, "span_s": [a, b], "samples_in": rows,
                      "gaps": gaps, "gap_bridge_limit_s": split_report["gap_bridge_limit_s"]}
        kept.append((name, result, split_from))
    limit, band = split_report["gap_bridge_limit_s"], split_report.get("motion_band_hz")
    rule = (f"longer than {limit:.3g} s, {100 * BRIDGE:g} % of the shortest period of its motion (band {band:.3g} "
            "Hz), so interpolation would invent the motion in them") if band else \
        f"with no stretch of 256 samples to read the motion's band from, every gap over {MAX_GAP:g} median steps"
    named = "; ".join(f"{g['length_s']:.6g} s after t = {g['t_s']:.6g} s" for g in cut)
    bridged = len(gaps) - len(cut)
    if not kept:
        raise DataError(f"{path}: field 't': {len(cut)} gap(s) too long to bridge ({rule}: {named}) cut the log into "
                        f"{total} stretches, none long enough to be processed: {'; '.join(dropped)}; expected a "
                        "stretch between gaps longer than the low-pass' transients (or a log without such gaps)")
    notes = [f"'{base}' ({pathlib.Path(path).name}) is split at {len(cut)} gap(s) too long to bridge ({rule}): "
             f"{named}; its data sets are " + ", ".join(f"'{n}' ({s['span_s'][0]:.6g} to {s['span_s'][1]:.6g} s)"
                                                       for n, _, s in kept)
             + (f"; {bridged} shorter gap(s) bridged by interpolation" if bridged else "")]
    if dropped:
        notes.append(f"'{base}': stretch(es) between gaps too short to be processed, dropped: {'; '.join(dropped)}")
    return kept, notes


def _frf(arrs, path, robot):
    return frf_arrays(arrs, path, robot.joint_names)


def _modal(arrs, path, robot):
    return modal_arrays(arrs, path, robot.joint_names)


def _response(arrs, path, robot):
    # the torque sets' compiled batch inverse dynamics: one compile per robot structure
    from ..torque._set import _id_batch, on_rows

    return response_arrays(arrs, path, robot.joint_names, lambda *x: on_rows(_id_batch, (robot,), x))


_LOADERS = {"frf": _frf, "modal": _modal, "response": _response}
_CONFIG_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


def case_path(base: pathlib.Path, rel: str, field: str, case_file, allow_outside: bool = False) -> pathlib.Path:
    """``rel`` (a path case.yaml gives in ``field``) resolved against the case folder ``base``.

    Unless ``allow_outside``, an absolute path and one that leaves the folder (``..``, or a
    symbolic link pointing out, resolved first) raise :class:`ConfigError` naming the field; the
    file is not opened.
    """
    if "\x00" in rel:
        raise _err(case_file, field, f"{rel[:80]!r} contains a NUL byte; expected a file path")
    p = pathlib.Path(rel)
    if allow_outside:
        return base / p
    hint = "case files lie inside the case folder (pass allow_outside=True, or --allow-outside to jflex diagnose, to read it)"
    if p.is_absolute() or p.drive:
        raise _err(case_file, field, f"absolute path {rel!r}: {hint}")
    root = base.resolve()
    if not (base / p).resolve().is_relative_to(root):
        raise _err(case_file, field, f"{rel!r} resolves outside the case folder: {hint}")
    return base / p


def _load_robot(spec: str, base, file, allow_outside):
    within = None  # a robot YAML in the case names its URDF inside the case folder too (unless allowed out)
    if pathlib.PurePath(spec).suffix.lower() in (".urdf", ".yaml", ".yml"):
        rp = case_path(base, spec, "robot", file, allow_outside)
        target = str(rp)
        within = None if allow_outside else base
    elif _CONFIG_NAME.match(spec):
        target = spec
    else:
        raise _err(file, "robot", f"expected a .urdf/.yaml file or a config name such as panda, got {spec!r}")
    try:
        return load_robot(target, within=within)
    except JFlexError as exc:
        raise ConfigError(f"{file}: field 'robot': {exc}") from None


def _refuse_mimic(robot, file):
    """A robot with coupled (<mimic>) joints is refused by name: every effect of the diagnosis (the
    nominal friction, each candidate) indexes joints as coordinates, which a follower has none of
    (jflex.Model refuses effects on it), and its data would need a column per coordinate."""
    mimic = getattr(robot, "mimic", ())
    pairs = [(robot.joint_names[i], robot.joint_names[k]) for i, k in enumerate(mimic) if k >= 0]
    if pairs:
        raise _err(file, "robot", "joints coupled by <mimic> are not supported by the diagnosis ("
                   + ", ".join(f"{f} follows {lead}" for f, lead in pairs) + "); expected a robot without them: "
                   "lock the leaders, which locks their followers (robot: {file: ..., lock: {"
                   + ", ".join(f"{lead}: 0.0" for lead in dict.fromkeys(lead for _, lead in pairs))
                   + "}}), or keep only the other joints (robot: {file: ..., joints: [...]})")


def _load_reduced_robot(rs, base, file, allow_outside):
    """The robot of a ``robot: {file, joints, lock}`` entry: a URDF (or a robot YAML / config name
    resolving to one) reduced to ``joints``, the others locked (:func:`jflex.load_urdf`)."""
    from ..._config import _example_robot_urdf, robot_from_config
    from ..._urdf import load_urdf

    spec = rs.file
    suffix = pathlib.PurePath(spec).suffix.lower()
    red = {k: v for k, v in (("joints", rs.joints), ("lock", rs.lock)) if v is not None}
    try:
        if suffix == ".urdf":
            return load_urdf(case_path(base, spec, "robot.file", file, allow_outside), **red)
        if suffix in (".yaml", ".yml"):
            rp = case_path(base, spec, "robot.file", file, allow_outside)
            cfg = load_yaml(rp)
            if not isinstance(cfg, dict) or "urdf" not in cfg:
                raise _err(file, "robot.joints", f"{rp.name} is not a robot YAML naming a URDF (urdf:); only a URDF "
                           "robot is reduced")
            cfg = {**cfg, **red}
            return robot_from_config(cfg, where=str(rp), base=rp.parent, within=None if allow_outside else base)
        if not _CONFIG_NAME.match(spec):
            raise _err(file, "robot.file", f"expected a .urdf/.yaml file or a config name such as panda, got {spec!r}")
        urdf = _example_robot_urdf(spec)
        if urdf is None:
            raise _err(file, "robot.file", f"{spec!r} is not a robot whose URDF can be reduced (joints/lock need a "
                       "URDF: name the .urdf file)")
        return load_urdf(urdf, **red)
    except ConfigError:
        raise
    except JFlexError as exc:
        raise ConfigError(f"{file}: field 'robot': {exc}") from None


def _nominal(specs, robot, file) -> list[dict]:
    nominal, seen = [], {}
    for i, e in enumerate(specs):
        fld = f"nominal_effects[{i}]"
        joints = _resolve_joints(e.joint, robot, file, fld + ".joint")
        for j in joints:
            if (e.effect, j) in seen:
                raise _err(file, fld + ".joint", f"effect {e.effect!r} at joint {j!r} is already given by "
                           f"{seen[(e.effect, j)]}; give each effect once per joint")
            seen[(e.effect, j)] = fld
        d = {"effect": e.effect, "joints": joints}
        for k in EFFECT_VALUES.get(e.effect, ()):
            v = getattr(e, k)
            if v is None:
                continue
            if len(v) not in (1, len(joints)):
                raise _err(file, f"{fld}.{k}", f"expected a number or {len(joints)} numbers (one per joint "
                           f"{list(joints)}), got {len(v)}")
            d[k] = np.broadcast_to(np.asarray(v, dtype=float), (len(joints),)).copy()
        nominal.append(d)
    return nominal




def _window(arrs: dict, window, path, fld: str, case_file) -> dict:
    """The samples of a time record (``t`` and every array with a time axis: the first one, the
    second one of ``*_repeats``) inside ``window`` = [start, end] seconds from its first stamp."""
    t = np.asarray(arrs["t"], float)
    rel = t - t[0]
    keep = window_mask(t, window)
    if keep.sum() < MIN_WINDOW_SAMPLES:
        raise _err(case_file, f"{fld}.window", f"{list(window)} s keeps {int(keep.sum())} samples of {path.name} "
                   f"(its record lasts {rel[-1]:.4g} s): expected a window inside the record with at least 20")
    return window_rows(arrs, keep)


def _case_robot(spec, base, file, allow_outside):
    """The case's robot, its inertia replaced by ``robot_inertia`` when given, and the robot's
    warnings (passed on): ``(robot, notes)``. Refuses coupled joints, unknown ``keep_channels``
    and an unknown ``tool_frame``."""
    # the robot's warnings (a massless link, a non-physical inertia) are the user's to see, and the
    # report's: passed on, and kept
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if isinstance(spec.robot, RobotSpec):
            robot = _load_reduced_robot(spec.robot, base, file, allow_outside)
        else:
            robot = _load_robot(spec.robot, base, file, allow_outside)
    notes = []
    for w in caught:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if issubclass(w.category, UserWarning):
            notes.append(str(w.message))
    _refuse_mimic(robot, file)
    unknown = [j for j in spec.options.keep_channels if j not in robot.joint_names]
    if unknown:
        raise _err(file, "options.keep_channels", f"unknown joints {unknown}; expected joint names of the model "
                   f"{list(robot.joint_names)}")
    if spec.robot_inertia is not None:
        # link parameters realised from identified base parameters need not be physically
        # consistent per link (only their combinations are identified): taken as they are
        ip = case_path(base, spec.robot_inertia, "robot_inertia", file, allow_outside)
        arr = load_npz_fields(ip, "robot_inertia", file, ("inertia",))
        if "inertia" not in arr:
            raise DataError(f"{ip}: field 'inertia': missing ((n, 10) link parameters in Pinocchio's order)")
        P = numeric_field(arr["inertia"], ip, "inertia", ndim=2)
        if P.shape != (robot.nq, 10):
            raise DataError(f"{ip}: field 'inertia': expected shape ({robot.nq}, 10), got {P.shape}")
        robot = robot.replace(inertia=P)
    tool = spec.tool_frame
    if tool is not None:
        try:
            robot.frame_index(tool)
        except JFlexError:
            raise _err(file, "tool_frame", f"unknown frame {tool!r}; frames: {list(robot.link_names) + list(robot.frame_names)}") from None
    return robot, notes


def log_map(d, robot, file, fld: str) -> LogMap:
    """The case.yaml data set ``d`` (``fld``: ``datasets[i]`` of ``file``) as the plain log map the
    readers take: its column map, scales, units, coupling and posture, the model's joints, and
    ``(file, fld)`` for their messages."""
    cols, cp, units = d.columns, d.coupling, d.units
    return LogMap(
        d.kind, {} if cols is None else {k: getattr(cols, k) for k in type(cols).model_fields},
        tuple(robot.joint_names), d.scale or {}, d.offset or {},
        None if cp is None else {"joints": list(cp.joints), "matrix": cp.matrix, "angles": cp.angles},
        d.torque_offset or {}, units.time if units is not None else "s", units.position if units is not None else "rad",
        d.rate, d.delimiter, d.q0, d.quantity, d.topic, (file, fld))


def _read_dataset(d, fld: str, base, file, robot, allow_outside):
    """The :class:`jflex.data.Record` of the data set ``d`` (``fld`` in case.yaml), read by its
    file's format and cut to its window: ``(record, first file, every file)``."""
    from ...data._csv import read_csv
    from ...data._npz import read_npz
    from ...data._record import Record
    from ...data._rosbag import read_rosbag
    from ...data._uff import uff_arrays

    many = isinstance(d.file, list)
    fpaths = [case_path(base, f, f"{fld}.file" + (f"[{k}]" if many else ""), file, allow_outside)
              for k, f in enumerate(d.file if many else [d.file])]
    fpath = fpaths[0]
    fmt = file_format(fpaths[0].name if many else d.file, base)
    if fmt == "csv":
        rec = read_csv(fpaths, log_map(d, robot, file, fld))
    elif fmt == "rosbag":
        rec = read_rosbag(fpath, log_map(d, robot, file, fld))
    elif fmt == "uff":
        rec = Record(uff_arrays(fpath, log_map(d, robot, file, fld)))
    else:
        rec = read_npz(fpath, f"{fld}.file", file, NPZ_KEYS[d.kind])
    if d.window is not None:
        rec.arrays = _window(rec.arrays, d.window, fpath, fld, file)
        rec.conditioning["window_s"] = list(d.window)
    return rec, fpath, fpaths


def _torque_datasets(d, rec, cond, fpath, fpaths, robot, options):
    """The data sets of one torque log (one, or one per stretch of a log split at gaps too long to
    bridge): ``(data sets, notes)``; the notes are warned of and kept with the first stretch."""
    from ...data._record import Record

    stretches, split_report, extra = torque_arrays(rec.arrays, fpath, robot.joint_names, options, split=True)
    kept, notes_split = _stretches(stretches, split_report, d.name or fpath.stem, fpath, options)
    datasets = []
    for piece_name, (data, report, excluded), split_from in kept:
        pcond, channels = dict(cond), dict(rec.channels)
        if "sampling" in pcond:  # the reader resampled already: its numbers describe the raw stamps
            report["sampling"] = {**report["sampling"], **pcond.pop("sampling")}
        if split_from is not None:
            report["sampling"]["split_from"] = split_from
        pcond.update(report)
        piece = Record(rec.arrays, channels)
        for j, c in report["channels"].items():
            if c["flags"]:
                piece.flag(f"tau:{j}", *c["flags"])
        datasets.append(Dataset(d.kind, fpath, d.split, piece_name, data, extra, pcond, excluded,
                                piece.channels, tuple(fpaths)))
    for msg in notes_split:
        warnings.warn(msg, UserWarning, stacklevel=3)
        datasets[-len(kept)].conditioning.setdefault("warnings", []).append(msg)
    return datasets, notes_split


def load_case(path, *, allow_outside: bool = False) -> Case:
    """Read and validate a case folder (or its ``case.yaml``).

    **Arguments:**

    - ``path``: the folder holding ``case.yaml``, or the YAML file itself.
    - ``allow_outside``: let ``robot``, ``robot_inertia`` and data ``file`` paths leave the case
      folder (absolute paths, ``..``); off by default, so a case reads only its own files.

    **Returns:** a :class:`Case`. Raises :class:`jflex.ConfigError` / :class:`jflex.DataError`
    naming the file and field of the first problem found. A torque log with gaps too long to
    bridge is split at them into several data sets (see :class:`Dataset`), a stretch too short
    for the low-pass dropped; both are warned of (a ``UserWarning``, kept in ``Case.warnings`` and
    the first stretch's ``conditioning["warnings"]``). The schema of ``case.yaml`` is
    :class:`jflex.gap.case._schema.CaseSpec` (the table in ``docs/case_format.md``).
    """
    p = pathlib.Path(path)
    file = p / "case.yaml" if p.is_dir() else p
    if not file.is_file():
        raise ConfigError(f"{file}: case file not found (a case is a folder with case.yaml)")
    base = file.parent
    spec = validate(CaseSpec, load_yaml(file), file, context={"folder": base})
    robot, notes = _case_robot(spec, base, file, allow_outside)
    tool = spec.tool_frame
    nominal = _nominal(spec.nominal_effects, robot, file)
    datasets, specs, split_notes = [], [], []
    for i, d in enumerate(spec.datasets):
        fld = f"datasets[{i}]"
        if d.kind == "frf" and tool is None:
            raise _err(file, "tool_frame", f"needed by the frf data set {fld} (FRFs are at the tool frame)")
        rec, fpath, fpaths = _read_dataset(d, fld, base, file, robot, allow_outside)
        cond, excluded = dict(rec.conditioning), ()
        if d.kind == "torque":
            kept, notes_split = _torque_datasets(d, rec, cond, fpath, fpaths, robot, spec.options.model_dump())
            datasets, specs, split_notes = datasets + kept, specs + [d] * len(kept), split_notes + notes_split
            continue
        arrs = rec.arrays
        if d.kind == "response":
            arrs, sampling = uniform_response(arrs, fpath)
            if sampling is not None:
                cond["sampling"] = {**sampling, **cond.get("sampling", {})}
        data, extra = _LOADERS[d.kind](arrs, fpath, robot)
        if d.kind == "response" and tool is None and any(c in TIP_CHANNELS for c in data["channels"]):
            raise _err(file, "tool_frame", f"needed by the response data set {fld} ({fpath.name}): its tip channels "
                       "are positions of the tool frame")
        datasets.append(Dataset(d.kind, fpath, d.split, d.name or fpath.stem, data, extra, cond, excluded,
                                rec.channels, tuple(fpaths)))
        specs.append(d)
    names = [d.name for d in datasets]
    if len(set(names)) != len(names):
        raise _err(file, "datasets", f"data set names must be unique, got {names}")
    if not any(d.split == "train" for d in datasets):
        raise _err(file, "datasets", "no data set has split: train (the nominal model is fitted on it)")
    if not any(d.split == "validation" for d in datasets):
        raise _err(file, "datasets", "no data set has split: validation (the gap is judged on held-out data)")
    _refuse_long_delay(nominal, datasets, file)
    sets_notes = _held_out_notes(specs, datasets) + _short_training_notes(spec, nominal, datasets, robot)
    for d, msg in sets_notes:
        warnings.warn(msg, UserWarning, stacklevel=2)
        d.conditioning.setdefault("warnings", []).append(msg)
    if notes:  # the robot's: with the first training set's, where the report's data notes show them
        first = next(d for d in datasets if d.split == "train")
        first.conditioning["warnings"] = notes + first.conditioning.get("warnings", [])
    # noise: only what the case states (the diagnosis reports a default as such); options: all,
    # defaults filled
    noise = spec.noise.model_dump(exclude_none=True)
    return Case(file, robot, tool, nominal, datasets, noise, spec.options.model_dump(),
                notes + split_notes + [m for _, m in sets_notes])


DELAY_SHARE = 0.1  # a nominal sensor delay is a small lag of the record, at most this share of it


def _duration(d) -> float | None:
    t = d.arrays.get("t") if d.kind in ("torque", "response") else None
    return None if t is None or np.size(t) < 2 else float(np.max(t) - np.min(t))


def _refuse_long_delay(nominal, datasets, file) -> None:
    """A nominal ``sensor_delay`` shifts every record by its value: one of a sizeable share of the
    shortest record leaves nothing to compare (and is a unit slip: ms written as s)."""
    spans = [(_duration(d), d.name) for d in datasets if _duration(d)]
    if not spans:
        return
    span, name = min(spans)
    for i, e in enumerate(nominal):
        if e["effect"] == SENSOR_DELAY and "value" in e and float(np.max(e["value"])) > DELAY_SHARE * span:
            raise _err(file, f"nominal_effects[{i}].value", f"a delay of {float(np.max(e['value'])):.4g} s against the "
                       f"record '{name}' of {span:.4g} s: expected a delay well below the record length (at most "
                       f"{DELAY_SHARE:g} x it, {DELAY_SHARE * span:.3g} s; a delay is given in seconds)")


def _span(window):
    a, b = (window or [0.0, None])
    return float(a), float("inf") if b is None else float(b)


def _held_out_notes(specs, datasets) -> list:
    """``(validation set, sentence)`` for each validation set that holds the same samples as a
    training set (the same file and overlapping windows, or the same torques): the gap is then
    judged on data the model was fitted on, and nothing is held out. ``specs``: the case.yaml
    entry of each data set (the stretches of a split log share theirs)."""
    out = []
    for v, vs in zip(datasets, specs):
        if v.split != "validation":
            continue
        for t, ts in zip(datasets, specs):
            if t.split != "train" or t.kind != v.kind:
                continue
            (a0, a1), (b0, b1) = _span(ts.window), _span(vs.window)
            overlap = min(a1, b1) - max(a0, b0)
            same_file = tuple(t.files) == tuple(v.files) and overlap > 0
            ta, va = t.arrays.get("tau"), v.arrays.get("tau")
            same_data = (ta is not None and va is not None and np.shape(ta) == np.shape(va)
                         and np.array_equal(ta, va))
            if same_file or same_data:
                how = (f"overlapping windows of {', '.join(p.name for p in v.files)}" if same_file and not same_data
                       else "the same samples")
                out.append((v, f"validation set '{v.name}' and training set '{t.name}' hold {how}: nothing is held "
                               "out, so the gap is judged on data the model was fitted on (an effect can look "
                               "explained that held-out data would not confirm); expected a validation set of "
                               "other samples (another log, or 'jflex case init --hold-out')"))
                break
    return out


# equations (training samples x torque channels) per fitted parameter below which the nominal
# identification is warned of: a least-squares fit of p parameters on r rows leaves r - p degrees
# of freedom for the residual (and the noise floor read off it)
ROWS_PER_PARAMETER = 10


def _short_training_notes(spec, nominal, datasets, robot) -> list:
    """``(training set, sentence)`` when the torque training data are too short to identify the
    nominal model: fewer than ``ROWS_PER_PARAMETER`` equations per parameter fitted (10 inertial
    parameters per link when they are refitted, one coefficient per nominal friction term and
    joint)."""
    train = [d for d in datasets if d.split == "train" and d.kind == "torque"]
    if not train:
        return []
    n = robot.nq
    params = (10 * n if spec.options.refit_inertia else 0) + sum(
        len(e["joints"]) for e in nominal if e["effect"] != JOINT_FLEXIBILITY and "value" not in e)
    rows = sum(int(np.shape(d.arrays["tau"])[0]) * n for d in train)
    if params == 0 or rows >= ROWS_PER_PARAMETER * params:
        return []
    samples = sum(int(np.shape(d.arrays["tau"])[0]) for d in train)
    return [(train[0], f"the torque training data are too short to identify the nominal model: {samples} samples x "
                       f"{n} joints = {rows} equations for {params} parameters (expected at least "
                       f"{ROWS_PER_PARAMETER} equations per parameter, {-(-ROWS_PER_PARAMETER * params // n)} samples "
                       "here); the fit follows the noise and the verdict is weak")]
