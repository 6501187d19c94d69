"""``import jflex`` and ``import jflex.identify`` stay light: SciPy's signal and statistics
packages and matplotlib (seconds of import each) load only where a function uses them."""

import json
import subprocess
import sys

HEAVY = ("scipy.signal", "scipy.stats", "matplotlib")
PROBE = f"import json, sys; print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))"


def loaded_at_each_stage(*stages):
    code = "\n".join(f"{stage}\n{PROBE}" for stage in stages)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    return [json.loads(line) for line in res.stdout.strip().splitlines()[-len(stages):]]


def test_heavy_modules_load_only_where_used():
    after_jflex, after_identify, after_ema = loaded_at_each_stage(
        "import jflex",
        # the equation-error path a user takes first: regressor, base parameters, least squares
        "import jflex.identify as I\nI.ols, I.base_parameters, I.Regressor, I.physical_fit, I.fit",
        "import numpy as np\nI.peak_picking(np.arange(64.0), 1 / (1 + (np.arange(64.0) - 30) ** 2))",
    )
    assert after_jflex == []
    assert after_identify == []
    assert "scipy.signal" in after_ema  # the probe itself can see a loaded module


def test_least_squares_identification_does_not_import_scipy():
    # a fresh identification process pays for every import: SciPy's linear algebra alone is
    # 0.3 s of a TIAGo identification's 3 s, and NumPy gives what the path needs
    code = (
        "import sys, numpy as np, jflex\n"
        "from jflex import identify as idf\n"
        "robot = jflex.from_dh([[0, 0, 0.3, 0], [0, 0.4, 0, 1.5708], [0, 0.3, 0, 0]])\n"
        "reg = idf.Regressor(viscous=True, coulomb=True)\n"
        "bp = idf.base_parameters(robot, reg)\n"
        "q, qd, qdd = idf.random_samples(robot, 200, seed=1)\n"
        "A = np.asarray(reg.stack(robot, q, qd, qdd))[:, list(bp.independent)]\n"
        "np.linalg.lstsq(A, np.ones(A.shape[0]), rcond=None)\n"
        "print(bp.rank, sorted(m for m in sys.modules if m == 'scipy' or m.startswith('scipy.')))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    rank, loaded = res.stdout.strip().splitlines()[-1].split(" ", 1)
    assert int(rank) > 0
    assert loaded == "[]"
