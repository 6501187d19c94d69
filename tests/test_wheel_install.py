"""jflex installed from a wheel (not editable) works from a folder outside the source tree: the
configs and experiment scripts ship inside the package, so ``jflex run --list``, ``jflex info
staubli_tx200`` and the experiments find them.

The wheel is built from a copy of the checkout (``pip wheel --no-build-isolation``, offline) and
installed with ``--no-deps --no-index`` into a fresh venv that sees this interpreter's packages
for jflex's dependencies (:func:`_venv_seeing_these_packages`: also when pytest itself runs in a
venv, whose packages ``--system-site-packages`` would not show). Every command runs with its working
directory in a temporary folder, and the test checks that the venv's ``jflex`` is the installed
one, not this checkout's.

The tests that need the installed wheel are marked ``experiments``: CI runs them (with every
experiment's ``--quick`` run) in its step after the suite, ``pytest -m experiments``, which
builds the wheel once for them all; a plain ``pytest`` skips them."""

from __future__ import annotations

import importlib.util
import json
import os
import pathlib
import shutil
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _can_build_wheel() -> bool:
    import setuptools

    major, minor = (int(x) for x in setuptools.__version__.split(".")[:2])
    # setuptools >= 70.1 has bdist_wheel itself; older ones need the `wheel` package
    return (major, minor) >= (70, 1) or importlib.util.find_spec("wheel") is not None


def _run(cmd, cwd, timeout=600, env=None, check=True):
    env = {**os.environ, **(env or {})}
    for key in ("PYTHONPATH", "JFLEX_CONFIGS"):
        env.pop(key, None)
    res = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    if check:
        assert res.returncode == 0, f"{cmd} -> {res.returncode}\n{res.stdout[-3000:]}\n{res.stderr[-3000:]}"
    return res


def _copy_source(dst: pathlib.Path) -> pathlib.Path:
    ignore = shutil.ignore_patterns(".git", "runs", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache",
                                    ".hypothesis", ".whl", ".gl", "tests", "benchmarks", "docs")
    shutil.copytree(ROOT, dst, ignore=ignore)
    return dst


def _venv_seeing_these_packages(env_dir: pathlib.Path, cwd) -> None:
    """A venv at ``env_dir`` that sees the packages of the interpreter running the tests.

    ``python -m venv --system-site-packages`` run from a venv builds on that venv's base
    interpreter and shows the base's packages, not the venv's (where a user's jax is): so a .pth
    in the new venv adds each site folder of this interpreter with ``site.addsitedir`` (the
    folders' own .pth files included, e.g. where cmeel puts Pinocchio). They come after the new
    venv's own site-packages, so the jflex installed there is the one imported."""
    import site
    import sysconfig

    # no pip of its own (ensurepip is slow): the pip it sees through this interpreter's packages
    # installs into it
    _run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", str(env_dir)], cwd=cwd)
    dirs = list(site.getsitepackages())
    if site.ENABLE_USER_SITE and os.path.isdir(site.getusersitepackages()):
        dirs.append(site.getusersitepackages())
    py = env_dir / "bin" / "python"
    purelib = _run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=cwd).stdout.strip()
    assert purelib != sysconfig.get_paths()["purelib"], "the new venv is this interpreter's own environment"
    pathlib.Path(purelib, "_jflex_test_parent_env.pth").write_text(
        "import site; " + "; ".join(f"site.addsitedir({d!r})" for d in dirs) + "\n")


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    if not _can_build_wheel():
        pytest.skip("building a wheel offline needs setuptools >= 70.1 or the 'wheel' package")
    base = tmp_path_factory.mktemp("wheel")
    src = _copy_source(base / "src")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
          "-w", str(base / "dist"), str(src)], cwd=base)
    (wheel,) = (base / "dist").glob("jflex-*.whl")
    env_dir = base / "venv"
    _venv_seeing_these_packages(env_dir, cwd=base)
    py = env_dir / "bin" / "python"
    _run([str(py), "-m", "pip", "install", "--no-deps", "--no-index", "-q", str(wheel)], cwd=base)
    assert (env_dir / "bin" / "jflex").is_file()
    work = base / "elsewhere"
    work.mkdir()
    return py, env_dir / "bin" / "jflex", work


def test_pyproject_lists_every_jflex_package():
    # pyproject lists the packages (to map configs/ and experiments/ into the wheel): a new
    # subpackage must be added there, or the wheel ships without it
    import tomllib

    from setuptools import find_packages

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    assert set(find_packages(str(ROOT), include=["jflex*"])) | {"jflex.configs", "jflex.experiments"} == listed


@pytest.mark.experiments
def test_installed_jflex_is_not_the_checkout(venv):
    py, _, work = venv
    # one process: where jflex and its shipped folders are, then `run --list` with those folders
    # gone, which must be an error (an install that lost its scripts printed nothing, exit 0)
    code = ("import sys, jflex, jflex._paths as p, jflex.cli as c\n"
            "print(jflex.__file__); print(*p.shipped_dirs('configs')); print(*p.shipped_dirs('experiments'))\n"
            "p.shipped_dirs = c.shipped_dirs = lambda kind: []\n"
            "sys.stdout.flush(); sys.exit(c.main(['run', '--list']))")
    res = _run([str(py), "-c", code], cwd=work, check=False)
    out = res.stdout.split("\n")
    installed = pathlib.Path(out[0]).resolve()
    assert ROOT not in installed.parents and "site-packages" in installed.parts, (installed, res.stderr[-2000:])
    for line in out[1:3]:
        assert line and ROOT not in pathlib.Path(line).resolve().parents and installed.parent in pathlib.Path(line).parents, out
    assert res.returncode == 2 and "no experiment scripts found" in res.stderr, (res.returncode, res.stderr)


@pytest.mark.experiments
def test_run_list_info_and_load_robot_installed(venv):
    py, jflex, work = venv
    listing = _run([str(jflex), "run", "--list"], cwd=work).stdout
    shipped = sorted(p.stem for p in (ROOT / "experiments").glob("*.py") if not p.name.startswith("_"))
    assert [line.split()[0] for line in listing.strip().splitlines()] == shipped, listing
    # `jflex info` and load_robot in one process (each interpreter start costs seconds)
    code = ("import jflex, jflex.cli as c; assert c.main(['info', 'staubli_tx200']) == 0; "
            "print('nq', jflex.load_robot('kuka_kr90').nq)")
    out = _run([str(py), "-c", code], cwd=work).stdout
    assert "joints: 3" in out and "nq 3" in out, out


TINY_VIBRATION = """
mass_kg: 1.0
stiffness_N_per_m: 400.0
damping_ratios: [0.05]
x0_m: 0.01
v0_m_per_s: 0.0
t_end_s: 0.2
samples: 21
forced: {force_N: 1.0, frequency_ratios: [2.0], damping_ratio: 0.5, settle_periods: 2.0}
duhamel: {damping_ratio: 0.05, pulse_N: 2.0, pulse_duration_s: 0.08}
rtol: 1.0e-6
atol: 1.0e-9
"""


@pytest.mark.experiments
def test_quick_experiment_installed(venv, tmp_path):
    # the vibration experiment on a tiny config (its default one takes half a minute)
    _, jflex, work = venv
    cfg = work / "tiny_vibration.yaml"
    cfg.write_text(TINY_VIBRATION)
    out = tmp_path / "run"
    _run([str(jflex), "run", "seed000_vibration", str(cfg), "--out", str(out)], cwd=work)
    res = json.loads((out / "results.json").read_text())
    # the simulated free response follows the closed form (the experiment's own check)
    assert res["free"][0]["max_error_m"] < 1e-5, res["free"]
    assert (out / "seed000_responses.png").is_file()


@pytest.mark.heavy  # the demo's diagnosis: about 35 s idle, minutes on two shared cores
def test_demo_installed(venv, tmp_path):
    _, jflex, work = venv
    out = tmp_path / "demo"
    _run([str(jflex), "demo", "--out", str(out)], cwd=work)
    assert (out / "results.json").is_file() and (out / "report.html").is_file()


ALL = sorted(p.stem for p in (ROOT / "experiments").glob("*.py") if not p.name.startswith("_"))


@pytest.mark.experiments
@pytest.mark.parametrize("name", ALL)
def test_every_experiment_quick_installed(venv, tmp_path, name):
    # each in its quick mode, which checks its key figures itself (exit 2 when one is off); up to
    # a minute each, so CI runs them in a step of their own (.ci/run: pytest -m experiments)
    _, jflex, work = venv
    res = _run([str(jflex), "run", name, "--quick", "--out", str(tmp_path / name)], cwd=work, timeout=900)
    checked = json.loads((tmp_path / name / "results.json").read_text())["quick_check"]
    assert checked and all(row["ok"] for row in checked.values()), (checked, res.stdout[-2000:])


@pytest.mark.heavy
@pytest.mark.parametrize("name", ALL)
def test_every_experiment_installed(venv, tmp_path, name):
    # each at its default config; minutes each on two shared cores, hence JFLEX_SLOW=1 only
    _, jflex, work = venv
    _run([str(jflex), "run", name, "--out", str(tmp_path / name)], cwd=work, timeout=3600)
    assert (tmp_path / name / "results.json").is_file() or any((tmp_path / name).iterdir())
