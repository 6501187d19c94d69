"""Cold start: time to ``import jflex`` and first-compile times of its kernels, against peers.

Run: ``python benchmarks/bench_startup.py [--repeat 3] [--out DIR]``.

Each measurement runs in a fresh Python process (imports and compile caches are per process):

* ``import jax`` alone, then ``import jflex`` (the difference is what jflex adds);
* ``jflex --help`` and ``jflex --version`` as a user runs them (the console entry point);
* first compile (``jax.jit(f).lower(...).compile()``) of ``rnea``, ``crba``, ``forward_dynamics``
  (ABA and ``method="crba"``), ``jacobian``, ``linearize`` and ``modal_analysis`` on the 7-joint
  Panda of example-robot-data (fingers fixed), **with the robot passed as an argument** (traced
  leaves, what ``jax.jit(jflex.forward_dynamics)(robot, q, qd, tau)`` does) and, for the rigid
  kernels, with the robot closed over (its numbers folded into the program);
* the peers, where installed: ``import pinocchio`` plus its first ``rnea``/``aba`` call on the
  same Panda; ``import mujoco`` plus compiling the same URDF with MuJoCo's own compiler and a
  first ``mj_forward``; and, when ``mujoco.mjx`` is installed, its first ``mjx.forward`` compile
  on that model (the menagerie's Panda MJCF is not shipped, and nothing is downloaded).

Then what a user waits for on a realistic flexible robot, each in a fresh process from ``import``
to the first result (imports + model build + trace + compile + first run), beside the warm second
call in the same process: the Panda with ``FlexibleJoints`` on all 7 joints (14 coordinates,
motors held), ``jax.jit(jax.vmap(modal_analysis(..., solver="newton")))`` over a batch of
``--batch`` postures, and ``jflex.frf_sweep`` (newton, pole-residue) on ``--n-freq`` frequencies.

The linearised model is the Panda with flexible joints (``FlexibleJoints`` on all 7 joints), held
at the motor angles (``hold="actuated"``), the modal analysis the same model at the same posture.
The machine this runs on may be shared: rerun with ``--repeat`` and read the minimum.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import time

_HERE = pathlib.Path(__file__).resolve().parent

# one measurement = one fresh process running one of these snippets; it prints a JSON dict
_PANDA = """
import pathlib, jflex
from jflex._config import _example_robot_urdf
def panda7():
    path = str(_example_robot_urdf("panda"))
    text = pathlib.Path(path).read_text()
    for j in ("panda_finger_joint1", "panda_finger_joint2"):
        i = text.index(f'name="{j}"'); k = text.index('type="prismatic"', i)
        text = text[:k] + 'type="fixed"' + text[k + len('type="prismatic"'):]
    return jflex.from_urdf_string(text, name="panda7"), path
"""

_IMPORT = """
import json, time
t0 = time.perf_counter(); import jax; t1 = time.perf_counter(); import jflex; t2 = time.perf_counter()
print(json.dumps({"import jax": t1 - t0, "import jflex (beyond jax)": t2 - t1}))
"""

_COMPILE = _PANDA + """
import json, sys, time
import jax, jax.numpy as jnp
robot, _ = panda7()
n = robot.nq
q = jnp.linspace(0.1, 0.7, n); qd = jnp.linspace(-0.3, 0.4, n); tau = jnp.linspace(1.0, 2.0, n)
model = jflex.Model(robot, [jflex.effects.FlexibleJoints(jnp.full(n, 1e4), jnp.full(n, 5.0), jnp.full(n, 0.1), jnp.full(n, 50.0))])
fns = {
    "rnea": (lambda r, q, qd, t: jflex.rnea(r, q, qd, t), robot),
    "crba": (lambda r, q, qd, t: jflex.crba(r, q), robot),
    "forward_dynamics (aba)": (lambda r, q, qd, t: jflex.forward_dynamics(r, q, qd, t), robot),
    "forward_dynamics (crba)": (lambda r, q, qd, t: jflex.forward_dynamics(r, q, qd, t, method="crba"), robot),
    "jacobian": (lambda r, q, qd, t: jflex.jacobian(r, q, n - 1), robot),
    "linearize": (lambda m, q, qd, t: jflex.linear.linearization(m, q, hold="actuated")[1].K, model),
    "modal_analysis": (lambda m, q, qd, t: jflex.modal_analysis(m, q, hold="actuated").frequency, model),
}
name, mode = sys.argv[1], sys.argv[2]
f, arg = fns[name]
t0 = time.perf_counter()
if mode == "argument":
    low = jax.jit(f).lower(arg, q, qd, tau)
else:
    low = jax.jit(lambda q, qd, t: f(arg, q, qd, t)).lower(q, qd, tau)
t1 = time.perf_counter()
low.compile()
t2 = time.perf_counter()
print(json.dumps({"trace_s": t1 - t0, "compile_s": t2 - t1, "hlo_lines": low.as_text().count(chr(10))}))
"""

_PIN = _PANDA + """
import json, time
t0 = time.perf_counter(); import pinocchio as pin; t1 = time.perf_counter()
_, path = panda7()
full = pin.buildModelFromUrdf(path)
lock = [full.getJointId("panda_finger_joint1"), full.getJointId("panda_finger_joint2")]
model = pin.buildReducedModel(full, lock, pin.neutral(full)); data = model.createData()
import numpy as np
q = np.linspace(0.1, 0.7, 7); qd = np.linspace(-0.3, 0.4, 7)
t2 = time.perf_counter(); pin.rnea(model, data, q, qd, qd); pin.aba(model, data, q, qd, qd); t3 = time.perf_counter()
print(json.dumps({"import pinocchio": t1 - t0, "first rnea + aba": t3 - t2}))
"""

_MJX = _PANDA + """
import json, re, time
t0 = time.perf_counter(); import mujoco; t1 = time.perf_counter()
_, path = panda7()
xml = pathlib.Path(path).read_text()
xml = re.sub(r"<visual>.*?</visual>", "", xml, flags=re.S)
xml = re.sub(r"<collision>.*?</collision>", "", xml, flags=re.S)
t2 = time.perf_counter(); m = mujoco.MjModel.from_xml_string(xml); d = mujoco.MjData(m); mujoco.mj_forward(m, d)
t3 = time.perf_counter()
out = {"import mujoco": t1 - t0, "MjModel from URDF + first mj_forward": t3 - t2}
try:
    import jax
    from mujoco import mjx
except ImportError:
    out["mjx"] = "not installed"
else:
    mx = mjx.put_model(m); dx = mjx.make_data(mx)
    t4 = time.perf_counter(); jax.jit(mjx.forward).lower(mx, dx).compile(); out["mjx.forward first compile"] = time.perf_counter() - t4
print(json.dumps(out))
"""


_USER = """
import sys, time
t0 = time.perf_counter()
import json
import jax, jax.numpy as jnp, numpy as np
import jflex
what, batch, nf = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
robot = jflex.load_robot("panda")
n = robot.nq
model = jflex.Model(robot, [jflex.effects.FlexibleJoints(jnp.full(n, 1e4), jnp.full(n, 5.0), jnp.full(n, 0.1), jnp.full(n, 50.0))])
Q = jnp.asarray(np.random.default_rng(0).uniform(-1.0, 1.0, (batch, n)))
if what == "modal":
    f = jax.jit(jax.vmap(lambda q: jflex.modal_analysis(model, q, hold="actuated", solver="newton").frequency))
    run = lambda Q: jax.block_until_ready(f(Q))
else:
    omega = jnp.linspace(1.0, 2000.0, nf)
    run = lambda Q: jflex.frf_sweep(model, Q, omega, hold="actuated", progress=False)
run(Q)
t1 = time.perf_counter()
run(Q + 0.01)
t2 = time.perf_counter()
print(json.dumps({"first_s": t1 - t0, "warm_s": t2 - t1}))
"""


def run_snippet(code, *args, env=None):
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def time_command(argv):
    t0 = time.perf_counter()
    out = subprocess.run(argv, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    return dt if out.returncode == 0 else None


def best(rows):
    """Per key, the minimum over repeats (numbers) or the first value."""
    out = {}
    for r in rows:
        for k, v in r.items():
            if isinstance(v, (int, float)) and k in out and isinstance(out[k], (int, float)):
                out[k] = min(out[k], v)
            else:
                out.setdefault(k, v)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=1, help="fresh processes per measurement (minimum reported)")
    ap.add_argument("--only", nargs="*", default=None, help="compile measurements to run (default: all)")
    ap.add_argument("--no-peers", action="store_true")
    ap.add_argument("--batch", type=int, default=64, help="postures of the flexible Panda's modal and FRF sweeps")
    ap.add_argument("--n-freq", type=int, default=200, help="frequencies of the flexible Panda's frf_sweep")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    results = {}
    results["import"] = best([run_snippet(_IMPORT) for _ in range(args.repeat)])
    exe = pathlib.Path(sys.executable).with_name("jflex")
    cli = [str(exe)] if exe.exists() else [sys.executable, "-m", "jflex.cli"]
    results["cli"] = {
        "jflex --help": min(filter(None, [time_command(cli + ["--help"]) for _ in range(args.repeat)]), default=None),
        "jflex --version": min(filter(None, [time_command(cli + ["--version"]) for _ in range(args.repeat)]), default=None),
    }
    for k, v in {**results["import"], **results["cli"]}.items():
        print(f"{k:<40} {v:8.2f} s" if isinstance(v, float) else f"{k:<40} {v}", flush=True)
    names = ["rnea", "crba", "forward_dynamics (aba)", "forward_dynamics (crba)", "jacobian", "linearize", "modal_analysis"]
    names = [n for n in names if args.only is None or n in args.only]
    results["compile"] = {}
    print(f"{'first compile, Panda 7 joints':<40} {'robot as argument':>18} {'robot closed over':>18}")
    for name in names:
        row = {}
        for mode in ("argument", "closed"):
            r = best([run_snippet(_COMPILE, name, mode) for _ in range(args.repeat)])
            row[mode] = r
        results["compile"][name] = row
        fmt = lambda r: f"{r['compile_s']:7.2f} s ({r['hlo_lines']:>5} l)" if "compile_s" in r else r.get("error", "-")[:18]
        print(f"{name:<40} {fmt(row['argument']):>18} {fmt(row['closed']):>18}", flush=True)
    results["flexible_panda"] = {}
    print(f"{'flexible Panda (14 coordinates), ' + str(args.batch) + ' postures':<40} {'first (fresh)':>18} {'warm':>18}")
    for what, label in (("modal", "vmapped modal_analysis (newton)"), ("frf", f"frf_sweep ({args.n_freq} frequencies)")):
        r = best([run_snippet(_USER, what, str(args.batch), str(args.n_freq)) for _ in range(args.repeat)])
        results["flexible_panda"][label] = r
        row = (f"{r['first_s']:16.2f} s {r['warm_s']:16.3f} s" if "first_s" in r else r.get("error", "-"))
        print(f"{label:<40} {row}", flush=True)
    if not args.no_peers:
        results["pinocchio"] = best([run_snippet(_PIN) for _ in range(args.repeat)])
        results["mjx"] = best([run_snippet(_MJX) for _ in range(args.repeat)])
        for peer in ("pinocchio", "mjx"):
            for k, v in results[peer].items():
                print(f"{peer + ': ' + k:<40} {v:8.2f} s" if isinstance(v, float) else f"{peer + ': ' + k:<40} {v}", flush=True)
    if args.out:
        pathlib.Path(args.out).mkdir(parents=True, exist_ok=True)
        (pathlib.Path(args.out) / "bench_startup.json").write_text(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()
