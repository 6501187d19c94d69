"""Cold start: ``import jflex`` loads only what it needs, every public name still resolves, and the
command line answers ``--help``, ``--version`` and ``run --list`` without loading the analyses."""

import json
import pathlib
import subprocess
import sys

import pytest

REPO = pathlib.Path(__file__).resolve().parent.parent

# every public name of jflex before the imports became lazy (dir(jflex) at commit 6a14f1b), less the
# thesis robot model, since moved to experiments/_machining_robot.py
PUBLIC = [
    "AbstractInput", "Beam", "Brake", "Chirp", "ConfigError", "DataError", "Function", "JFlexError", "Layout",
    "Linearization", "Model", "ParameterError", "Ramp", "Response", "Robot", "Sampled",
    "ShapeError", "SolverError", "Step", "URDFError", "Zero", "aba", "available_robots", "batched",
    "beam_modal_matrices", "beam_roots", "bias_forces", "check_inertia", "clamped_free_frequencies", "crba",
    "dynamic_stiffness", "effects", "experiment_cli", "fem", "forward_dynamics", "forward_kinematics",
    "frame_placement", "frf", "frf_sweep", "from_dh", "from_urdf_string", "gap", "gravity", "gravity_stiffness",
    "identify", "initial_state", "input_matrix", "jacobian", "kinetic_energy", "lagrangian_bias",
    "lagrangian_forward_dynamics", "lagrangian_mass_matrix", "linear", "linearize", "load_robot", "load_urdf",
    "load_yaml", "mac", "make_beam", "make_robot", "make_run_dir", "mass_matrix", "modal_analysis",
    "model_forward_dynamics", "model_inverse_dynamics", "nonlinear_effects", "potential_energy", "regressor",
    "rnea", "robot_from_config", "simulate",
    "stability_lobes", "state_rate", "sweep", "total_energy", "track_modes", "tune_allocator", "write_results",
]

# what `import jflex` must not load (each costs 0.1-0.5 s; they load when an analysis needs them)
HEAVY = ["scipy.signal", "scipy.optimize", "scipy.stats", "diffrax", "optimistix", "matplotlib", "jflex.gap",
         "jflex.identify", "jflex.linear", "jflex.fem", "jflex._simulate"]


def _python(code):
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_every_public_name_resolves():
    import importlib
    import types

    import jflex

    for name in PUBLIC:
        obj = getattr(jflex, name)
        assert obj is not None, name
    assert set(PUBLIC) <= set(dir(jflex))
    assert set(PUBLIC) <= set(jflex.__all__)
    # the lazy table points at the objects the private modules define (not copies)
    assert jflex.rnea is importlib.import_module("jflex._dynamics").rnea
    assert jflex.sweep is importlib.import_module("jflex._sweep").sweep
    assert isinstance(jflex.gap, types.ModuleType) and jflex.gap.__name__ == "jflex.gap"
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        jflex.not_a_name


def test_import_loads_no_analysis_package():
    code = (
        "import sys, time, json; t0 = time.perf_counter(); import jax; t1 = time.perf_counter(); import jflex; "
        "t2 = time.perf_counter(); robot = jflex.load_robot('staubli_tx200'); m = jflex.Model(robot); "
        f"print(json.dumps({{'loaded': [m for m in {HEAVY!r} if m in sys.modules], 'jax_s': t1 - t0, 'jflex_s': t2 - t1}}))"
    )
    r = json.loads(_python(code).strip().splitlines()[-1])
    # a robot, its dynamics and a Model still need none of them
    assert r["loaded"] == [], r
    print(f"import jax {r['jax_s']:.2f} s, import jflex beyond jax {r['jflex_s']:.3f} s")


def test_cli_version_and_help_without_analyses():
    import jflex

    code = (
        "import sys, contextlib, io\nfrom jflex.cli import main\nbuf = io.StringIO()\n"
        "with contextlib.redirect_stdout(buf):\n"
        "    try:\n        main(['--help'])\n    except SystemExit:\n        pass\n"
        f"print(buf.getvalue()); print('LOADED', [m for m in {HEAVY!r} if m in sys.modules])"
    )
    out = _python(code)
    assert "LOADED []" in out
    for cmd in ("info", "demo", "run", "diagnose", "--version"):
        assert cmd in out
    out = _python("from jflex.cli import main\ntry:\n    main(['--version'])\nexcept SystemExit:\n    pass")
    assert out.strip() == f"jflex {jflex.__version__}"


def test_run_list_one_line_per_experiment(capsys):
    from jflex.cli import experiment_summary, main

    scripts = sorted(p for p in (REPO / "experiments").glob("*.py") if not p.name.startswith("_"))
    assert main(["run", "--list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [ln.split()[0] for ln in lines] == [p.stem for p in scripts]
    for ln, p in zip(lines, scripts):
        summary = experiment_summary(p)
        assert ln.endswith(summary) and len(summary) > 20 and "\n" not in summary
    # run --help lists them too; an unknown name says which exist
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = capsys.readouterr().out
    assert all(p.stem in out for p in scripts)
    assert main(["run", "no_such_experiment"]) == 2
    assert "posture_modal" in capsys.readouterr().err


def test_experiment_summary_first_sentence(tmp_path):
    from jflex.cli import experiment_summary

    p = tmp_path / "x.py"
    p.write_text('"""First part of a sentence that\ncontinues here. Second sentence.\n\nMore."""\n')
    assert experiment_summary(p) == "First part of a sentence that continues here."
    p.write_text("x = 1\n")
    assert experiment_summary(p) == "(no docstring)"
