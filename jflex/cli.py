"""The ``jflex`` command. Every subcommand takes a YAML config (with a default), accepts
``--out DIR`` and writes ``DIR/results.json`` plus its plots (see :mod:`jflex._runs`)."""

from __future__ import annotations

import argparse
import ast
import importlib
import json
import importlib.util
import os
import pathlib
import re
import sys

import numpy as np

from . import __version__
from ._config import available_robots, config_dirs, load_robot, robot_from_config
from ._errors import JFlexError
from ._paths import shipped_dirs
from ._runs import load_yaml, make_run_dir, write_results

_PLUGINS = ("jflex.gap._cli",)


def _load_plugin(name: str):
    """A plugin module loaded from its file, without running its package's ``__init__`` (the gap
    package loads SciPy, diffrax and optimistix; ``jflex --help`` needs only the parsers). Its
    relative imports still resolve: the package itself is imported when a command runs."""
    parts = name.split(".")
    path = pathlib.Path(__file__).resolve().parent.joinpath(*parts[1:]).with_suffix(".py")
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or not path.is_file():
        return importlib.import_module(name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def experiments() -> dict[str, pathlib.Path]:
    """``experiments/*.py`` by name: the working directory's first, then the ones jflex ships
    (the installed package's, or the source checkout's)."""
    found: dict[str, pathlib.Path] = {}
    for base in (pathlib.Path.cwd() / "experiments", *shipped_dirs("experiments")):
        if base.is_dir():
            for path in sorted(base.glob("*.py")):
                if not path.name.startswith("_"):
                    found.setdefault(path.stem, path)
    return dict(sorted(found.items()))


def load_experiment(name: str, path: pathlib.Path):
    """Execute an experiment script as module ``jflex_experiment_<name>``. The module is registered
    in ``sys.modules`` before it runs: pydantic resolves the string annotations that
    ``from __future__ import annotations`` leaves (``Annotated[...]``) through the module's entry
    there, and a schema class defined in an unregistered module stays "not fully defined"."""
    mod_name = f"jflex_experiment_{name}"
    spec = importlib.util.spec_from_file_location(mod_name, path)
    if spec is None or spec.loader is None:
        raise JFlexError(f"{path}: not a Python script jflex run can load")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        sys.modules.pop(mod_name, None)
        raise
    return mod


def experiment_summary(path: pathlib.Path, width: int = 110) -> str:
    """The first sentence of a script's docstring, on one line (read, not executed)."""
    try:
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8"))) or ""
    except (OSError, SyntaxError, UnicodeDecodeError):
        return "(docstring unreadable)"
    para = " ".join(doc.strip().split("\n\n")[0].split())
    m = re.search(r"(?<=[a-z0-9)\]])\.(\s|$)", para)
    line = para[: m.start() + 1] if m else para
    if len(line) > width:
        line = line[: width - 3].rsplit(" ", 1)[0] + "..."
    return line or "(no docstring)"


def _experiment_table() -> str:
    ex = experiments()
    w = max((len(k) for k in ex), default=0)
    return "\n".join(f"  {k:<{w}}  {experiment_summary(p)}" for k, p in ex.items())


def _default_config(name: str) -> pathlib.Path:
    """``configs/<name>`` of the working directory, else the one jflex ships."""
    bases = [pathlib.Path.cwd() / "configs", *shipped_dirs("configs")]
    for base in bases:
        if (base / name).is_file():
            return base / name
    raise JFlexError(f"default config {name} not found in {', '.join(str(b) for b in bases)}: "
                     "is jflex installed complete? (pass a config path)")


def _robot_yaml_text(spec: str) -> dict:
    """The ``source`` and ``notes`` of the robot YAML ``spec`` names (empty for a URDF)."""
    path = pathlib.Path(spec)
    if path.suffix.lower() not in (".yaml", ".yml"):
        path = next((d / f"{spec}.yaml" for d in config_dirs() if (d / f"{spec}.yaml").is_file()), None)
    if path is None or not path.is_file():
        return {}
    cfg = load_yaml(path)
    return {k: " ".join(str(cfg[k]).split()) for k in ("source", "notes") if cfg.get(k)}


def cmd_info(args) -> int:
    robot = load_robot(args.robot)
    coupled = f" ({robot.nq} coordinates: mimic joints follow their leaders)" if robot.n_joints != robot.nq else ""
    print(f"robot: {args.robot}   joints: {robot.n_joints}{coupled}   base: {robot.base_name}")
    for key, text in _robot_yaml_text(str(args.robot)).items():
        print(f"{key}: {text}")
    masses = np.asarray(robot.inertia)[:, 0]
    if not np.any(masses > 0):
        print("note: no link masses or inertias (all zero): kinematics only; torques are zero and M(q) is singular")
    if np.all(np.isinf(np.asarray(robot.lower))) and np.all(np.isinf(np.asarray(robot.upper))):
        print("note: no joint limits given (all infinite)")
    print(f"gravity: {np.asarray(robot.gravity).tolist()} m/s^2")
    hdr = f"{'#':>2} {'joint':<22} {'type':<9} {'parent':<18} {'lower':>9} {'upper':>9} {'vel':>8} {'effort':>8} {'mass[kg]':>9}"
    print(hdr)
    print("-" * len(hdr))
    for i in range(robot.n_joints):
        rev = robot.joint_types[i] == "revolute"
        conv = np.rad2deg if rev else (lambda x: x)
        par = robot.link_names[robot.parents[i]] if robot.parents[i] >= 0 else robot.base_name
        lo, hi = conv(float(robot.lower[i])), conv(float(robot.upper[i]))
        print(
            f"{i:>2} {robot.joint_names[i]:<22} {robot.joint_types[i]:<9} {par:<18} {lo:>9.4g} {hi:>9.4g} "
            f"{float(robot.velocity_limit[i]):>8.4g} {float(robot.effort_limit[i]):>8.4g} {float(robot.inertia[i, 0]):>9.4g}"
        )
    print("(limits in deg for revolute joints, m for prismatic; velocity in rad/s or m/s; effort in N m or N)")
    print(f"total mass: {float(np.sum(robot.inertia[:, 0])):.4g} kg")
    if robot.frame_names:
        print("frames: " + ", ".join(robot.frame_names))
    return 0


def run_demo(cfg: dict, run_dir: pathlib.Path, case_robot=None) -> dict:
    """Gravity torques and mass-matrix conditioning over a (q2, q3) grid: of ``case_robot``
    (``(name, Robot)``, the robot the demo diagnosed) when the config's ``robot`` is ``case``, else
    of the named robot."""
    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from . import _dynamics as dyn
    from ._sweep import sweep

    spec = cfg.get("robot", "case")
    robot_cfg = None
    if spec == "case":
        if case_robot is None:
            raise JFlexError("demo: robot 'case' maps the robot of the diagnosed case; pass a robot config name or URDF")
        spec = f"{case_robot[0]} (the robot diagnosed, CAD inertias)"
    for d in config_dirs() if case_robot is None else ():
        if (d / f"{spec}.yaml").is_file():
            robot_cfg = load_yaml(d / f"{spec}.yaml")
            break
    if robot_cfg is not None and "links" in cfg:
        robot_cfg["links"] = cfg["links"]
        robot = robot_from_config(robot_cfg, where=f"demo robot '{spec}'")
    elif case_robot is not None:
        robot = case_robot[1]
    else:
        robot = load_robot(spec)
    g = cfg.get("grid", {})
    n = int(g.get("n", 61))
    q2 = np.deg2rad(np.linspace(*g.get("q2_deg", [-120, 120]), n))
    q3 = np.deg2rad(np.linspace(*g.get("q3_deg", [-140, 140]), n))
    Q2, Q3 = np.meshgrid(q2, q3, indexing="ij")
    q = np.zeros((n * n, robot.nq))
    q[:, 1], q[:, 2] = Q2.ravel(), Q3.ravel()

    def one(qi):
        M = dyn.crba(robot, qi)
        ev = jax.numpy.linalg.eigvalsh(M)
        return {"g": dyn.gravity(robot, qi), "cond": ev[-1] / ev[0], "tip": dyn.frame_placement(robot, qi, "tool")[:3, 3]}

    out = sweep(one, q, chunk_size=1024, label="demo sweep")
    G = out["g"].reshape(n, n, robot.nq)
    cond = out["cond"].reshape(n, n)
    fig, axs = plt.subplots(1, 3, figsize=(15, 4.2))
    ext = [np.rad2deg(q3[0]), np.rad2deg(q3[-1]), np.rad2deg(q2[0]), np.rad2deg(q2[-1])]
    for k, (ax, data, title) in enumerate(
        zip(axs, [G[..., 1], G[..., 2], np.log10(cond)], ["gravity torque joint 2 [N m]", "gravity torque joint 3 [N m]", "log10 cond M(q)"])
    ):
        im = ax.imshow(data, origin="lower", extent=ext, aspect="auto", cmap="viridis")
        ax.set_xlabel("q3 [deg]")
        ax.set_ylabel("q2 [deg]")
        ax.set_title(f"{spec}:\n{title}", fontsize=10)
        fig.colorbar(im, ax=ax)
    fig.tight_layout()
    fig.savefig(run_dir / "gravity_maps.png", dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(5, 5))
    tip = out["tip"]
    sc = ax.scatter(np.hypot(tip[:, 0], tip[:, 1]) * np.sign(tip[:, 0]), tip[:, 2], c=np.abs(out["g"][:, 1]), s=3)
    fig.colorbar(sc, ax=ax, label="|gravity torque of joint 2| [N m]")
    ax.set_xlabel("reach [m]")
    ax.set_ylabel("height [m]")
    ax.set_title(f"{spec}:\ntool positions over the (q2, q3) grid")
    ax.set_aspect("equal")
    fig.savefig(run_dir / "workspace.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    i2 = np.unravel_index(np.argmax(np.abs(G[..., 1])), G.shape[:2])
    return {
        "robot": spec,
        "grid_points": n * n,
        "max_abs_gravity_torque_Nm": np.abs(out["g"]).max(axis=0),
        "worst_posture_joint2_deg": [0.0, float(np.rad2deg(q2[i2[0]])), float(np.rad2deg(q3[i2[1]]))],
        "mass_matrix_condition_max": float(cond.max()),
        "mass_matrix_condition_min": float(cond.min()),
        "plots": ["gravity_maps.png", "workspace.png"],
    }


def _run(name, default, fn, args, schema=None) -> int:
    cfg = load_yaml(args.config or default)
    if schema is not None:  # unset optional keys stay absent: run_demo tests `"links" in cfg`
        from ._schema import validate

        cfg = validate(schema, cfg, args.config or default).model_dump(exclude_none=True)
    run_dir = make_run_dir(name, args.out)
    results = dict(fn(cfg, run_dir))
    results.setdefault("config", str(args.config or default))
    write_results(run_dir, results)
    print(f"{name}: results in {run_dir / 'results.json'}")
    return 0


def run_gap_demo(cfg: dict, run_dir: pathlib.Path) -> dict:
    """The main job: diagnose the built-in case (a 3-joint arm whose data hide a payload and
    Coulomb friction), then rigid posture maps beside it: of the diagnosed robot (``robot: case``,
    the default of ``configs/demo.yaml``) or of the robot the config names."""
    import json

    from .gap import demo as gap_demo

    report = gap_demo(run_dir)
    diag = json.loads((run_dir / "diagnosis.json").read_text())
    rigid_dir = run_dir / "rigid_maps"
    rigid_dir.mkdir(exist_ok=True)
    from .gap import load_case

    case_robot = None
    if cfg.get("robot", "case") == "case":
        case_dir = run_dir / "case"
        rfile = case_dir / load_yaml(case_dir / "case.yaml")["robot"]
        name = load_yaml(rfile).get("name", rfile.stem) if rfile.suffix in (".yaml", ".yml") else rfile.stem
        case_robot = (name, load_case(case_dir).robot)
    rigid = run_demo(cfg, rigid_dir, case_robot)
    from .gap.report._report import add_figures

    add_figures(run_dir, [(f"rigid_maps/{p}", cap) for p, cap in zip(rigid["plots"], (
        "Gravity torques of joints 2 and 3 and the mass matrix's conditioning (log10) over the (q2, q3) grid.",
        "The tool's positions over the same grid, coloured by joint 2's gravity torque."))],
        f"Rigid posture maps of {rigid['robot']}")
    print(f"\ndiagnosis report: {report}")
    return {
        "report": str(report),
        "gap_before_percent": diag.get("gap_before"),
        "gap_after_percent": diag.get("gap_after"),
        "noise_floor_percent": diag.get("noise_floor"),
        "selected": [{"effect": e.get("effect"), "joint": e.get("joint"), "shrink_percent": e.get("shrink")} for e in diag.get("selected", [])],
        "rigid_maps": rigid,
        "plots": [p.name for p in sorted(run_dir.glob("*.png"))],
    }


def cmd_demo(args) -> int:
    from ._demo_config import DemoConfig

    return _run("demo", args.config or _default_config("demo.yaml"), run_gap_demo, args, schema=DemoConfig)


def cmd_run(args) -> int:
    """Run ``experiments/<name>.py`` with the remaining arguments (``--list``: list them)."""
    if args.list:
        if not experiments():
            raise JFlexError(
                "no experiment scripts found: none in ./experiments, and this jflex install ships none "
                f"(looked in {', '.join(str(d) for d in shipped_dirs('experiments')) or 'jflex/experiments'})"
            )
        print(_experiment_table())
        return 0
    if args.experiment is None:
        print("jflex run: name an experiment:\n" + _experiment_table(), file=sys.stderr)
        return 2
    path = experiments().get(args.experiment)
    if path is None:
        raise JFlexError(
            f"no experiment '{args.experiment}' in experiments/; available: {', '.join(experiments())} "
            "(jflex run --list describes them)"
        )
    mod = load_experiment(args.experiment, path)
    if not hasattr(mod, "main"):
        raise JFlexError(f"{path}: an experiment script must define main(argv)")
    mod.main(args.rest)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jflex", description="Differentiable dynamics of flexible manipulators (JAX).")
    p.add_argument("--version", action="version", version=f"jflex {__version__}")
    p.add_argument("--cache-dir", default=None, metavar="DIR",
                   help="keep compiled programs in DIR and reuse them in later runs (default: $JFLEX_CACHE_DIR, "
                   "else ~/.cache/jflex/jax; delete the folder to clear it)")
    p.add_argument("--no-cache", action="store_true",
                   help="compile everything afresh and keep nothing on disk (also: JFLEX_NO_CACHE=1)")
    sub = p.add_subparsers(dest="command", required=True)
    pi = sub.add_parser("info", help="print joints, limits and masses of a robot")
    pi.add_argument("robot", help=f"YAML/URDF path or a name ({', '.join(available_robots())})")
    pi.set_defaults(fn=cmd_info)
    pd = sub.add_parser("demo", help="run the main job on the built-in example")
    pd.add_argument("config", nargs="?", default=None, help="YAML config (default: configs/demo.yaml)")
    pd.add_argument("--out", default=None, help="run folder (default: runs/demo-<time>)")
    pd.set_defaults(fn=cmd_demo)
    pr = sub.add_parser(
        "run", help="run an experiment script from experiments/ (--list: what each does)",
        description="Run experiments/<EXPERIMENT>.py; the arguments after its name go to the script.\n"
        "Each takes [CONFIG] [--out DIR] [--quick]; --quick is a small run on the experiment's quick config\n"
        "that checks its key figures (e.g. jflex run posture_modal --quick).", epilog="experiments:\n" + _experiment_table(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    pr.add_argument("--list", action="store_true", help="list the experiments, one line each, and exit")
    pr.add_argument("experiment", nargs="?", default=None, help="name of a script in experiments/")
    pr.add_argument("rest", nargs=argparse.REMAINDER, help="arguments passed to the script: [CONFIG] [--out DIR] [--quick]")
    pr.set_defaults(fn=cmd_run)
    # Subsystems register their own subcommands: each module exposes add_subcommands(sub),
    # whose parsers set ``fn`` like the ones above.
    for mod in _PLUGINS:
        try:
            module = _load_plugin(mod)
        except ImportError:
            continue
        module.add_subcommands(sub)
    return p


def _clock_for(args):
    # the commands that compute (not --help-like ones): how much of them was tracing and compiling
    if getattr(args, "command", None) not in ("demo", "run", "diagnose") or getattr(args, "list", False):
        return None
    from ._compile_clock import CompileClock

    return CompileClock()


def _report_clock(clock, args) -> None:
    print(f"jflex {args.command}: {clock.line()}", file=sys.stderr)
    out = getattr(args, "out", None)
    if out and pathlib.Path(out).is_dir():
        (pathlib.Path(out) / "compile_time.json").write_text(json.dumps(clock.summary(), indent=1) + "\n")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        # a run of the command line compiles the same programs as the last run on the same robot:
        # JAX's persistent cache makes the second run start warm (the API leaves it opt-in). Every
        # program is stored, also those that compile in under 0.1 s: the demo's 41 such programs
        # took its warm run from 62 to 56 % of cold (16.2 -> 14.4 s against 26 s, load about 1)
        if not (args.no_cache or os.environ.get("JFLEX_NO_CACHE", "") not in ("", "0")):
            from ._compilation_cache import enable_compilation_cache

            enable_compilation_cache(args.cache_dir, min_compile_time_s=0.0)
        clock = _clock_for(args)
        code = args.fn(args)
        if clock is not None:
            _report_clock(clock, args)
        return code
    except JFlexError as exc:
        print(f"jflex: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
