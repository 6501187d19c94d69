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
