"""benchmarks/bench_gpu.py runs on CPU at its tiny size: every kernel, modal solver and FRF
sweep it times is checked against Pinocchio, SciPy's eig or the direct FRF, and it says which
host callbacks remain in the compiled kernels (MJX rows only where mujoco-mjx is installed)."""

import json
import pathlib
import subprocess
import sys

import pytest

BENCH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "bench_gpu.py"


# the CI runs the rigid kernels in float64 (one process); every kernel in both precisions (two
# processes, the derivative kernels compile for minutes on two cores) with JFLEX_SLOW=1
FULL = (["rnea", "crba", "aba", "rnea_derivatives", "aba_derivatives"], ["float64", "float32"])
SMALL = (["rnea", "crba", "aba"], ["float64"])


@pytest.mark.slow
@pytest.mark.parametrize("kernels,dtypes", [pytest.param(*SMALL, id="small"),
                                            pytest.param(*FULL, id="full", marks=pytest.mark.heavy)])
def test_bench_gpu_tiny_runs_and_checks_its_results(tmp_path, kernels, dtypes):
    res = subprocess.run([sys.executable, str(BENCH), "--size", "tiny", "--kernels", *kernels, "--dtypes", *dtypes,
                          "--out", str(tmp_path)], capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    out = json.loads((tmp_path / "bench_gpu.json").read_text())
    assert out["backend"] == "cpu" and out["size"] == "tiny"
    rows = out["rows"]
    got = {(r["kernel"], r["dtype"]) for r in rows if "dtype" in r and r.get("program") != "mjx"}
    assert {(k, d) for k in kernels for d in dtypes} <= got
    for r in rows:
        if r.get("program") == "mjx":
            continue
        assert "error" not in r, r
        assert r["ok"], r
        if "out_dtype" in r:
            assert r["out_dtype"] == r["dtype"], r  # float32 runs in float32 (a JFLEX_X64=0 process)
    assert {(r["kernel"], r["solver"]) for r in rows if "solver" in r} == {
        ("modal_analysis", "eig"), ("modal_analysis", "newton"), ("frf_sweep", "eig"), ("frf_sweep", "newton")}
