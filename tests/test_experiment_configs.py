"""Every experiment's config has a schema: the shipped configs validate to what the script reads
today (plus defaults), and an unknown key, a negative physical number, a string where a number
belongs and a NaN are refused with a ConfigError naming the file and the field. Nothing runs."""

from __future__ import annotations

import copy
import functools
import math
import pathlib

import pytest

import jflex
from jflex._schema import field_path, validate

ROOT = pathlib.Path(__file__).resolve().parent.parent

# experiment: (schema class, configs it reads, a field that must be > 0, a plain numeric field)
EXPERIMENTS = {
    "seed000_vibration": ("Seed000VibrationConfig", ["seed000_vibration.yaml", "seed000_vibration_quick.yaml"],
                          ("stiffness_N_per_m",), ("forced", "force_N")),
    "seed004_damping": ("Seed004DampingConfig", ["seed004_rigid_flexible_arm.yaml", "seed004_rigid_flexible_arm_quick.yaml"],
                        ("arm", "EI3_N_m2"), ("initial_tip_deflection_m",)),
    "seed001_rp_arm": ("Seed001RpArmConfig", ["seed001_rp_arm_quick.yaml", "seed001_rp_arm.yaml",
                                           "seed001_rp_arm_one_variant.yaml"],
                       ("joint", "stiffness_N_m_per_rad"), ("loading", "revolute_torque_N_m")),
    "gap_seed001": ("GapSeed001Config", ["gap_seed001.yaml", "gap_seed001_full.yaml", "gap_seed001_quick.yaml"],
                    ("start", "joint_stiffness_N_m_per_rad"), ("noise", "q1_deg")),
    "gap_seed002": ("GapSeed002Config", ["gap_seed002.yaml", "gap_seed002_quick.yaml"], ("gap", "noise", "sigma_mm"), ("gap", "zeta")),
    "identify_seed004": ("IdentifySeed004Config", ["identify_seed004.yaml", "identify_seed004_quick.yaml"], ("static", "planted", "EI3_N_m2"),
                         ("static", "loads_N", 1)),
    "identify_synthetic": ("IdentifySyntheticConfig", ["identify_synthetic.yaml", "identify_synthetic_quick.yaml"],
                           ("flexible_joints", "stiffness_N_m_per_rad", 1), ("rigid_friction", "compensator_N_m", 0)),
    # not an experiment script: `jflex demo` (jflex/cli.py) reads configs/demo.yaml
    "demo": ("DemoConfig", ["demo.yaml"], None, ("grid", "q2_deg", 0)),
    "press_bdc": ("PressBdcConfig", ["press.yaml", "press_quick.yaml"], ("press", "main_mass"), ("press", "crank_pivot", 0)),
    # these three use `from __future__ import annotations`: their schemas resolve only when the
    # script is registered in sys.modules before it runs, as jflex.cli.load_experiment does
    "posture_modal": ("PostureModalConfig", ["posture_modal.yaml", "posture_modal_quick.yaml"], ("frf", "f_min_Hz"), ("lobes", "spindle_rpm", 1)),
    "identify_seed003": ("IdentifySeed003Config", ["identify_seed003.yaml", "identify_seed003_quick.yaml"], ("start_factor",), ("weights", "frequency")),
    "seed003_prediction": ("PredictionConfig", ["seed003_prediction.yaml", "seed003_prediction_quick.yaml"], ("robots", 1, "wrist", "mass_kg"),
                           ("weights", "damping")),
}
# experiments that take no YAML config (only --out)
NO_CONFIG = {"gap_seed003"}


def test_every_experiment_has_a_quick_mode_whose_config_ships():
    # `jflex run NAME --quick` (CI runs each from the installed wheel): a config under configs/
    # and a check of the key figures; gap_seed003 takes no config, only the flag
    import re

    from jflex.cli import experiments

    for name, path in experiments().items():
        if path.parent != ROOT / "experiments":
            continue
        text = path.read_text()
        if name in NO_CONFIG:
            assert '"--quick"' in text and "quick_check(" in text, name
            continue
        m = re.search(r'quick=\((?:[\w."]+ / )*(?:DEFAULT\.with_name\()?"(\w+\.yaml)"', text)
        assert m and (ROOT / "configs" / m.group(1)).is_file() and "def quick_figures(" in text, name
        assert any(m.group(1) in cfgs for _, cfgs, _, _ in [EXPERIMENTS[name]]), (name, m.group(1))


def test_quick_check_refuses_a_figure_outside_its_bounds_or_not_finite(tmp_path, capsys):
    from jflex._runs import quick_check

    rows = quick_check("x", {"a [Hz]": (10.2, 9.9, 10.5)})
    assert rows == {"a [Hz]": {"value": 10.2, "low": 9.9, "high": 10.5, "ok": True}}
    for value in (10.6, math.nan):
        with pytest.raises(jflex.JFlexError, match=r"x --quick: b \[Hz\] = .* not in \[9\.9, 10\.5\]"):
            quick_check("x", {"a [Hz]": (10.2, 9.9, 10.5), "b [Hz]": (value, 9.9, 10.5)})
    assert "OUT OF" in capsys.readouterr().out
    # through experiment_cli: --quick takes the quick config, checks, and the results keep the rows
    (tmp_path / "full.yaml").write_text("n: 1\n")
    (tmp_path / "small.yaml").write_text("n: 2\n")
    run = lambda cfg, d: {"n": cfg["n"]}
    check = lambda res: {"n": (res["n"], 2, 2)}
    out = jflex.experiment_cli("x", tmp_path / "full.yaml", run, ["--quick", "--out", str(tmp_path / "q")],
                               quick=(tmp_path / "small.yaml", check))
    assert __import__("json").loads((out / "results.json").read_text())["quick_check"]["n"]["ok"] is True
    with pytest.raises(jflex.JFlexError, match="x --quick: n = 1 not in"):
        jflex.experiment_cli("x", tmp_path / "full.yaml", run, [str(tmp_path / "full.yaml"), "--quick", "--out",
                             str(tmp_path / "f")], quick=(tmp_path / "small.yaml", check))


@functools.lru_cache(maxsize=None)
def _module(name):
    # loaded by path with the loader `jflex run` uses (experiments are scripts, not a package)
    from jflex.cli import load_experiment

    return load_experiment(name, ROOT / "experiments" / f"{name}.py")


def test_every_experiment_config_has_a_schema_under_test():
    from jflex.cli import experiments

    scripts = {k: p for k, p in experiments().items() if p.parent == ROOT / "experiments"}
    assert set(scripts) == (set(EXPERIMENTS) - {"demo"}) | NO_CONFIG
    for name in NO_CONFIG:
        assert "schema=" not in scripts[name].read_text() and "experiment_cli(" not in scripts[name].read_text()


def _schema(name):
    if name == "demo":
        from jflex._demo_config import DemoConfig

        return DemoConfig
    return getattr(_module(name), EXPERIMENTS[name][0])


def _set(cfg, path, value):
    node = cfg
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value


def _read_the_same(got, given, where=""):
    """Every key the YAML gives reaches the script with the same value (defaults may be added)."""
    if isinstance(given, dict):
        assert isinstance(got, dict), where
        for k, v in given.items():
            assert k in got, f"{where}.{k} dropped"
            _read_the_same(got[k], v, f"{where}.{k}")
    elif isinstance(given, list):
        assert isinstance(got, (list, tuple)) and len(got) == len(given), where
        for i, (a, b) in enumerate(zip(got, given)):
            _read_the_same(a, b, f"{where}[{i}]")
    else:
        assert got == given and type(got) in (type(given), float), f"{where}: {got!r} != {given!r}"


CASES = [(name, cfg) for name, (_, cfgs, _, _) in EXPERIMENTS.items() for cfg in cfgs]


@pytest.mark.parametrize("name,config", CASES)
def test_shipped_config_validates_to_what_the_script_reads(name, config):
    raw = jflex.load_yaml(ROOT / "configs" / config)
    # `jflex demo` drops unset optional keys (run_demo tests `"links" in cfg`); experiment_cli keeps them
    got = validate(_schema(name), copy.deepcopy(raw), config).model_dump(exclude_none=name == "demo")
    _read_the_same(got, raw)


def _refused(name, mutate, field):
    cfg_name = EXPERIMENTS[name][1][0]
    cfg = jflex.load_yaml(ROOT / "configs" / cfg_name)
    mutate(cfg)
    with pytest.raises(jflex.ConfigError) as exc:
        validate(_schema(name), cfg, f"configs/{cfg_name}")
    msg = str(exc.value)
    assert f"configs/{cfg_name}" in msg and f"field '{field}'" in msg, msg
    return msg


@pytest.mark.parametrize("name", list(EXPERIMENTS))
def test_unknown_key_refused(name):
    msg = _refused(name, lambda c: c.update(not_a_key=1.0), "not_a_key")
    assert "allowed keys" in msg


@pytest.mark.parametrize("name", [n for n, e in EXPERIMENTS.items() if e[2] is not None])
def test_negative_physical_number_refused(name):
    path = EXPERIMENTS[name][2]
    msg = _refused(name, lambda c: _set(c, path, -1.0), field_path(path))
    assert "> 0" in msg


@pytest.mark.parametrize("name", list(EXPERIMENTS))
@pytest.mark.parametrize("bad", ["abc", math.nan, math.inf])
def test_string_or_non_finite_number_refused(name, bad):
    path = EXPERIMENTS[name][3]
    _refused(name, lambda c: _set(c, path, bad), field_path(path))


def test_demo_links_of_a_named_robot_are_checked():
    from jflex._demo_config import DemoConfig

    cfg = {"robot": "staubli_tx200", "links": [{"mass": 250.0, "com": [0, 0, -0.15], "inertia": [12, 0, 12, 0, 0, 9]},
                                               {"mass": -1.0, "com": [0.45, 0, 0.2], "inertia": [3, 0, 14, 0, 0, 14]}]}
    with pytest.raises(jflex.ConfigError, match=r"field 'links\[1\]\.mass'"):
        validate(DemoConfig, cfg, "demo.yaml")


def test_exponent_without_sign_is_a_number(tmp_path):
    # YAML 1.1 (PyYAML) reads 1.9e11 as a string; the shipped configs write E that way
    f = tmp_path / "c.yaml"
    f.write_text("a: 1.9e11\nb: -2E-3\nc: .5e2\nd: [1e5, 7]\ne: .e5\nf: 1e\n")
    assert jflex.load_yaml(f) == {"a": 1.9e11, "b": -2e-3, "c": 50.0, "d": [1e5, 7], "e": ".e5", "f": "1e"}


def test_demo_refuses_a_bad_config_before_running(tmp_path, capsys):
    from jflex.cli import main

    cfg = jflex.load_yaml(ROOT / "configs" / "demo.yaml")
    cfg["grid"]["n"] = "61"
    bad = tmp_path / "demo.yaml"
    bad.write_text(__import__("yaml").safe_dump(cfg))
    assert main(["demo", str(bad), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "field 'grid.n'" in err, err
    assert not (tmp_path / "run").exists()


def test_run_list_and_info_read_for_a_new_user(capsys):
    # no internal document names (seed numbers, issue numbers, an unnamed "thesis") in what a
    # user sees first; a kinematics-only robot says so
    import re

    from jflex.cli import main

    assert main(["run", "--list"]) == 0
    # the descriptions (the script names themselves are kept: renaming breaks users' commands)
    listing = "\n".join(line.split(None, 1)[1] for line in capsys.readouterr().out.strip().splitlines())
    assert not re.search(r"(?i)seed[ -]?\d|issue \d|thesis", listing), listing
    assert main(["info", "staubli_tx200"]) == 0
    info = capsys.readouterr().out
    assert "Posture Dependent Dynamics in Robotic Machining" in info and "no link masses" in info, info
    assert not re.search(r"(?i)seed[ -]\d|issue \d", info), info  # a path such as configs/seed003/ is fine
