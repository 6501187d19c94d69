"""jflex against Pinocchio (and the JAX peers when installed) on the same random Panda states.

Run: ``python benchmarks/bench_dynamics.py [--batches 1 1000 100000] [--out DIR]``.

The headline (``--section whole``, first in ``all``) is what a user waits for: a fresh process,
timed from launch, that imports jflex, loads the Panda, draws ``--whole-batch`` random states and
calls ``jflex.batched(f)`` once (compilation included), against a fresh process that imports
Pinocchio, loads the same arm and calls its ``rneaInParallel`` / ``abaInParallel`` (CRBA: its
loop). The table after it is the warm figure: ``jflex.batched(f)`` (what users call) beside plain
``jax.jit(jax.vmap(f))`` and ``jflex.sweep``.
Prints a table: time per evaluation for each library and the ratio Pinocchio / jflex (> 1: jflex
faster). Pinocchio is called in a Python loop, one state at a time, as a user would.
jflex is timed after warm-up with ``block_until_ready``; compile times are reported separately.
The arm is the 7-joint Panda of example-robot-data (fingers locked at zero).

``--section derivatives`` runs only the section of issue 14: ``jflex.rnea_derivatives`` and
``jflex.aba_derivatives`` against Pinocchio's ``computeRNEADerivatives``/``computeABADerivatives``
in a Python loop (Pinocchio 4.1 has no multi-threaded derivatives batch), and batched ``rnea``/``aba``
against Pinocchio's ``rneaInParallel``/``abaInParallel`` on ``--threads`` threads (default 2), at
``--deriv-batches`` (default 1e3 and 1e5). The default ``--section all`` runs it after the table.

``--malloc hugetlb`` (the default) re-runs the script with ``GLIBC_TUNABLES=glibc.malloc.hugetlb=1``
so that glibc backs its large mmapped blocks with transparent huge pages. Both libraries run in
that same process. The setting matters for jflex at batch 1e5: each call returns one fresh
array (39 MB for the Panda's CRBA), and glibc serves any block over 32 MB by mmap, so every
call page-faults through 9500 fresh 4 kB pages. Pinocchio's loop returns 1e5 small arrays from
the heap. ``--malloc default`` leaves the allocator as it is.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jflex
from jflex._config import _example_robot_urdf


def panda7():
    path = str(_example_robot_urdf("panda"))
    text = pathlib.Path(path).read_text()
    for j in ("panda_finger_joint1", "panda_finger_joint2"):
        i = text.index(f'name="{j}"')
        k = text.index('type="prismatic"', i)
        text = text[:k] + 'type="fixed"' + text[k + len('type="prismatic"') :]
    robot = jflex.from_urdf_string(text, name="panda7")
    import pinocchio as pin

    full = pin.buildModelFromUrdf(path)
    lock = [full.getJointId("panda_finger_joint1"), full.getJointId("panda_finger_joint2")]
    model = pin.buildReducedModel(full, lock, pin.neutral(full))
    return robot, model, path


def best_time(fn, reps=5):
    best = np.inf
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def bench_jflex(robot, q, qd, qdd, tau):
    """jflex as users call it: ``jflex.batched(f)`` (the default program) is the headline; plain
    ``jax.jit(jax.vmap(f))`` and ``jflex.sweep(f, ...)`` (one chunk, host NumPy outputs) beside it."""
    fns = {
        "rnea": lambda a, b, c, d: jflex.rnea(robot, a, b, c),
        "crba": lambda a, b, c, d: jflex.crba(robot, a),
        "fd (aba)": lambda a, b, c, d: jflex.forward_dynamics(robot, a, b, d, method="aba"),
        "fd (crba+chol)": lambda a, b, c, d: jflex.forward_dynamics(robot, a, b, d, method="crba"),
        "dtau/dq": lambda a, b, c, d: jax.jacfwd(lambda x: jflex.rnea(robot, x, b, c))(a),
    }
    out, compile_s, first, extra = {}, {}, {}, {}
    N = q.shape[0]
    for name, f in fns.items():
        jf = jflex.batched(f)
        t0 = time.perf_counter()
        jax.block_until_ready(jf(q, qd, qdd, tau))
        compile_s[name] = time.perf_counter() - t0
        out[name] = best_time(lambda: jax.block_until_ready(jf(q, qd, qdd, tau)))
        first[name] = np.asarray(jf(q, qd, qdd, tau))[:CHECK]
        plain = jax.jit(jax.vmap(f))
        jax.block_until_ready(plain(q, qd, qdd, tau))
        extra[name] = {"jit_vmap": best_time(lambda: jax.block_until_ready(plain(q, qd, qdd, tau)))}
        if N > 1:
            sw = lambda: jflex.sweep(f, q, qd, qdd, tau, chunk_size=N, progress=False)
            sw()  # compiles; later calls reuse the program
            extra[name]["sweep"] = best_time(sw)
    return out, compile_s, first, extra


CHECK = 64  # states whose results are checked against Pinocchio's


def check_against_pinocchio(model, first, q, qd, qdd, tau):
    """Max relative difference of jflex's timed results from Pinocchio's on the first states: a
    timing of a wrong program is no timing (an XLA miscompile once made batched RNEA O(1) wrong)."""
    import pinocchio as pin

    data = model.createData()
    n = min(CHECK, q.shape[0])
    ref = {
        "rnea": [pin.rnea(model, data, q[i], qd[i], qdd[i]).copy() for i in range(n)],
        "crba": [np.triu(pin.crba(model, data, q[i])) + np.triu(pin.crba(model, data, q[i]), 1).T for i in range(n)],
        "fd (aba)": [pin.aba(model, data, q[i], qd[i], tau[i]).copy() for i in range(n)],
        "fd (crba+chol)": [pin.aba(model, data, q[i], qd[i], tau[i]).copy() for i in range(n)],
    }
    out = {}
    for name, R in ref.items():
        R = np.array(R)
        out[name] = float(np.max(np.abs(first[name][:n] - R)) / np.max(np.abs(R)))
    return out


def bench_pinocchio(model, q, qd, qdd, tau):
    import pinocchio as pin

    data = model.createData()
    N = q.shape[0]
    fns = {
        "rnea": lambda i: pin.rnea(model, data, q[i], qd[i], qdd[i]),
        "crba": lambda i: pin.crba(model, data, q[i]),
        "fd (aba)": lambda i: pin.aba(model, data, q[i], qd[i], tau[i]),
        "fd (crba+chol)": None,
        "dtau/dq": lambda i: pin.computeRNEADerivatives(model, data, q[i], qd[i], qdd[i]),
    }
    out = {}
    for name, f in fns.items():
        if f is None:
            continue
        out[name] = best_time(lambda: [f(i) for i in range(N)], reps=2 if N > 1000 else 3)
    return out


def bench_mjx(path, q, qd, qdd):
    """MuJoCo MJX inverse dynamics on the same Panda, if mujoco-mjx is installed."""
    try:
        import mujoco
        from mujoco import mjx
    except ImportError:
        return None
    try:
        text = pathlib.Path(path).read_text()
        import re

        text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
        text = re.sub(r"<collision>.*?</collision>", "", text, flags=re.S)
        m = mujoco.MjModel.from_xml_string(text)
        mx = mjx.put_model(m)
        N = q.shape[0]
        nv = m.nv
        pad = lambda a: jnp.concatenate([a, jnp.zeros((N, nv - a.shape[1]))], axis=1)
        Q, QD, QDD = pad(q), pad(qd), pad(qdd)

        def inv(a, b, c):
            d = mjx.make_data(mx).replace(qpos=a, qvel=b, qacc=c)
            return mjx.inverse(mx, d).qfrc_inverse

        f = jax.jit(jax.vmap(inv))
        t0 = time.perf_counter()
        jax.block_until_ready(f(Q, QD, QDD))
        comp = time.perf_counter() - t0
        return {"rnea": best_time(lambda: jax.block_until_ready(f(Q, QD, QDD)))}, {"rnea": comp}
    except Exception as exc:  # a peer that fails on this robot is reported, not fatal
        print(f"  mjx: skipped ({type(exc).__name__}: {exc})")
        return None


def _strip_geometry(path):
    import re

    text = pathlib.Path(path).read_text()
    text = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    return re.sub(r"<collision>.*?</collision>", "", text, flags=re.S)


def bench_adam(path, joint_names, q, qd, qdd):
    """adam-robotics (JAX backend): mass matrix and bias forces (floating-base API, base fixed at identity)."""
    try:
        from adam.jax import KinDynComputations
    except ImportError:
        return None
    try:
        kd = KinDynComputations(_strip_geometry(path), list(joint_names))
        H = jnp.eye(4)
        z6 = jnp.zeros(6)
        fM = jax.jit(jax.vmap(lambda a: kd.mass_matrix(H, a)))
        fh = jax.jit(jax.vmap(lambda a, b: kd.bias_force(H, a, z6, b)))
        fr = jax.jit(jax.vmap(lambda a, b, c: (kd.mass_matrix(H, a)[6:, 6:] @ c) + kd.bias_force(H, a, z6, b)[6:]))
        times, comp = {}, {}
        for name, f, args in [("crba", fM, (q,)), ("rnea", fr, (q, qd, qdd))]:
            t0 = time.perf_counter()
            jax.block_until_ready(f(*args))
            comp[name] = time.perf_counter() - t0
            times[name] = best_time(lambda: jax.block_until_ready(f(*args)))
        return times, comp
    except Exception as exc:
        print(f"  adam: skipped ({type(exc).__name__}: {exc})")
        return None


def bench_jaxsim(path, joint_names, q, qd, qdd):
    """jaxsim inverse dynamics (floating-base API, base held still), if it installs and loads."""
    try:
        import jaxsim.api as js
    except ImportError:
        return None
    try:
        m = js.model.JaxSimModel.build_from_model_description(
            _strip_geometry(path), is_urdf=True, considered_joints=list(joint_names)
        )

        def inv(a, b, c):
            d = js.data.JaxSimModelData.build(model=m, joint_positions=a, joint_velocities=b)
            return js.model.inverse_dynamics(m, d, joint_accelerations=c, base_acceleration=jnp.zeros(6))[1]

        f = jax.jit(jax.vmap(inv))
        t0 = time.perf_counter()
        jax.block_until_ready(f(q, qd, qdd))
        comp = time.perf_counter() - t0
        return {"rnea": best_time(lambda: jax.block_until_ready(f(q, qd, qdd)))}, {"rnea": comp}
    except Exception as exc:  # e.g. its URDF importer needs a Gazebo executable
        print(f"  jaxsim: skipped ({type(exc).__name__}: {str(exc)[:120]})")
        return None


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 1000, 100000])
    ap.add_argument("--pin-max", type=int, default=100000, help="largest batch Pinocchio's loop runs")
    ap.add_argument("--out", default=None)
    ap.add_argument("--malloc", choices=["hugetlb", "default"], default="hugetlb",
                    help="glibc allocator setting for this process (see the module docstring)")
    ap.add_argument("--section", choices=["all", "dynamics", "derivatives", "whole"], default="all",
                    help="the rigid-body table, the derivatives section, the whole-process headline, or all")
    ap.add_argument("--whole-batch", type=int, default=100000, help="batch of the whole-process headline")
    ap.add_argument("--deriv-batches", type=int, nargs="+", default=[1000, 100000])
    ap.add_argument("--deriv-algorithms", nargs="+", default=list(DERIV_ALGORITHMS), choices=list(DERIV_ALGORITHMS))
    ap.add_argument("--threads", type=int, default=2, help="threads of Pinocchio's *InParallel batches")
    ap.add_argument("--host-devices", type=int, default=None,
                    help="CPU devices jflex's batched rnea/aba of the derivatives section also split over "
                         "(one core each; default: --threads, so both sides use as many cores)")
    args = ap.parse_args(argv)
    hd = args.threads if args.host_devices is None else args.host_devices
    flag = f"--xla_force_host_platform_device_count={hd}"
    if hd > 1 and flag not in os.environ.get("XLA_FLAGS", "") and argv is None:
        # XLA reads its flags once, when the backend starts: a fresh process
        env = dict(os.environ, XLA_FLAGS=" ".join(filter(None, [os.environ.get("XLA_FLAGS"), flag])))
        os.execve(sys.executable, [sys.executable, *sys.argv], env)
    tunable = "glibc.malloc.hugetlb=1"
    if args.malloc == "hugetlb" and tunable not in os.environ.get("GLIBC_TUNABLES", "") and argv is None:
        # glibc reads its tunables once at process start, so the setting needs a fresh process
        env = dict(os.environ, GLIBC_TUNABLES=":".join(filter(None, [os.environ.get("GLIBC_TUNABLES"), tunable])))
        os.execve(sys.executable, [sys.executable, *sys.argv], env)
    if args.section in ("all", "whole"):
        # the headline first, in fresh processes: imports, model loading and compilation included
        wrows = whole_process(args.whole_batch, args.threads)
        if args.out:
            pathlib.Path(args.out).mkdir(parents=True, exist_ok=True)
            (pathlib.Path(args.out) / "bench_whole_process.json").write_text(json.dumps({"rows": wrows}, indent=2))
        if args.section == "whole":
            return wrows
    robot, model, path = panda7()
    rng = np.random.default_rng(0)
    rows = []
    print(f"jax {jax.__version__} on {jax.devices()[0].platform} ({platform.processor() or platform.machine()}), float64, Panda 7 joints, "
          f"GLIBC_TUNABLES={os.environ.get('GLIBC_TUNABLES', '(unset)')}")
    for N in args.batches if args.section != "derivatives" else []:
        q = rng.uniform(-1.5, 1.5, (N, robot.nq))
        qd, qdd = rng.normal(size=(2, N, robot.nq))
        tau = jax.jit(jax.vmap(lambda a, b, c: jflex.rnea(robot, a, b, c)))(q, qd, qdd)
        jt, jc, first, jx = bench_jflex(robot, q, qd, qdd, np.asarray(tau))
        diffs = check_against_pinocchio(model, first, q, qd, qdd, np.asarray(tau))
        bad = {k: v for k, v in diffs.items() if not v < 1e-9}
        print(f"  batch {N}: max relative difference from Pinocchio " + ", ".join(f"{k} {v:.1e}" for k, v in diffs.items()))
        if bad:
            raise SystemExit(f"jflex results differ from Pinocchio's at batch {N}: {bad}; timings would be meaningless")
        pt = bench_pinocchio(model, q, qd, qdd, np.asarray(tau)) if N <= args.pin_max else {}
        mj = bench_mjx(path, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd))
        bench_jaxsim(path, robot.joint_names, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd))
        ad = bench_adam(path, robot.joint_names, jnp.asarray(q), jnp.asarray(qd), jnp.asarray(qdd))
        for name in jt:
            row = {
                "batch": N,
                "algorithm": name,
                "jflex_us": 1e6 * jt[name] / N,
                "jit_vmap_us": 1e6 * jx[name]["jit_vmap"] / N,
                "sweep_us": 1e6 * jx[name]["sweep"] / N if "sweep" in jx[name] else None,
                "jflex_compile_s": jc[name],
                "max_rel_diff_vs_pinocchio": diffs.get(name),
                "pinocchio_loop_us": 1e6 * pt[name] / N if name in pt else None,
                "mjx_us": 1e6 * mj[0][name] / N if mj and name in mj[0] else None,
            }
            row["adam_us"] = 1e6 * ad[0][name] / N if ad and name in ad[0] else None
            row["ratio_adam_over_jflex"] = row["adam_us"] / row["jflex_us"] if row["adam_us"] else None
            row["ratio_pin_over_jflex"] = row["pinocchio_loop_us"] / row["jflex_us"] if row["pinocchio_loop_us"] else None
            row["ratio_mjx_over_jflex"] = row["mjx_us"] / row["jflex_us"] if row["mjx_us"] else None
            rows.append(row)
    fmt = lambda v, f: "-" if v is None else f.format(v)
    print("jflex us: jflex.batched(f) (what users call); jit(vmap) and sweep beside it")
    print(f"{'batch':>7} {'algorithm':<15} {'jflex us':>10} {'jit(vmap)':>9} {'sweep us':>9} {'pin us':>9} {'pin/jflex':>9} {'mjx us':>9} {'mjx/jflex':>9} {'adam us':>9} {'adam/jflex':>10} {'compile s':>9}")
    for r in rows:
        print(
            f"{r['batch']:>7} {r['algorithm']:<15} {r['jflex_us']:>10.3f} {r['jit_vmap_us']:>9.3f} {fmt(r['sweep_us'], '{:9.3f}')} "
            f"{fmt(r['pinocchio_loop_us'], '{:9.3f}')} "
            f"{fmt(r['ratio_pin_over_jflex'], '{:9.2f}')} {fmt(r['mjx_us'], '{:9.3f}')} {fmt(r['ratio_mjx_over_jflex'], '{:9.2f}')} "
            f"{fmt(r['adam_us'], '{:9.3f}')} {fmt(r['ratio_adam_over_jflex'], '{:10.2f}')} {r['jflex_compile_s']:>9.2f}"
        )
    if args.out:
        pathlib.Path(args.out).mkdir(parents=True, exist_ok=True)
        (pathlib.Path(args.out) / "bench_dynamics.json").write_text(json.dumps({"jax": jax.__version__, "glibc_tunables": os.environ.get("GLIBC_TUNABLES"), "rows": rows}, indent=2))
    if args.section != "dynamics":
        drows = bench_derivatives(robot, model, args.deriv_batches, args.deriv_algorithms, args.threads,
                                  devices=jax.devices()[:hd] if hd > 1 else None)
        if args.out:
            (pathlib.Path(args.out) / "bench_derivatives.json").write_text(json.dumps({"jax": jax.__version__, "rows": drows}, indent=2))
    return rows


# ---- whole process: what a user waits for, from the interpreter's start to the answer ---------

_WHOLE_JFLEX = """
import sys, time
launch, name, N = float(sys.argv[1]), sys.argv[2], int(sys.argv[3])
sys.path.insert(0, sys.argv[4])
import numpy as np
import jflex
from bench_dynamics import panda7_jflex
robot = panda7_jflex()
rng = np.random.default_rng(0)
q = rng.uniform(-1.5, 1.5, (N, robot.nq)); qd, qdd = rng.normal(size=(2, N, robot.nq))
f = {"rnea": lambda a, b, c: jflex.rnea(robot, a, b, c), "crba": lambda a, b, c: jflex.crba(robot, a),
     "aba": lambda a, b, c: jflex.aba(robot, a, b, c)}[name]
out = np.asarray(jflex.batched(f)(q, qd, qdd))
print(time.time() - launch)
"""

_WHOLE_PIN = """
import sys, time
launch, name, N, threads = float(sys.argv[1]), sys.argv[2], int(sys.argv[3]), int(sys.argv[5])
sys.path.insert(0, sys.argv[4])
import numpy as np
import pinocchio as pin
from bench_dynamics import panda7_pinocchio
model = panda7_pinocchio()
rng = np.random.default_rng(0)
q = rng.uniform(-1.5, 1.5, (N, model.nq)); qd, qdd = rng.normal(size=(2, N, model.nq))
pool = pin.ModelPool(model, threads)
qT, vT, aT = (np.asfortranarray(x.T) for x in (q, qd, qdd))
if name == "crba":  # no crbaInParallel: a loop, as a user would write it
    data = model.createData()
    out = [pin.crba(model, data, x).copy() for x in q]
else:
    out = np.asarray(getattr(pin, name + "InParallel")(threads, pool, qT, vT, aT))
print(time.time() - launch)
"""


def panda7_jflex():
    return panda7()[0]


def panda7_pinocchio():
    return panda7()[1]


def whole_process(batch, threads=2, algorithms=("rnea", "crba", "aba")):
    """Fresh processes, the clock from launch (interpreter, imports, model loading, random states,
    compilation, one call): jflex's ``batched`` against Pinocchio's ``*InParallel`` on ``threads``
    threads (CRBA: Pinocchio's loop). Results are checked in the main table, not here."""
    import subprocess

    here = str(pathlib.Path(__file__).resolve().parent)
    rows = []
    print(f"\nwhole process, batch {batch}, load {os.getloadavg()[0]:.2f}:", flush=True)
    for name in algorithms:
        times = {}
        for side, code, extra in (("jflex", _WHOLE_JFLEX, []), ("pinocchio", _WHOLE_PIN, [str(threads)])):
            res = subprocess.run([sys.executable, "-c", code, str(time.time()), name, str(batch), here, *extra],
                                 capture_output=True, text=True, timeout=1800)
            if res.returncode != 0:
                raise SystemExit(res.stderr[-2000:])
            times[side] = float(res.stdout.strip().splitlines()[-1])
        rows.append({"batch": batch, "algorithm": name, "jflex_whole_s": times["jflex"],
                     "pinocchio_whole_s": times["pinocchio"], "ratio_pin_over_jflex": times["pinocchio"] / times["jflex"]})
        print(f"  {name:<5} jflex {times['jflex']:7.2f} s   Pinocchio ({'loop' if name == 'crba' else f'{threads}-thread batch'}) "
              f"{times['pinocchio']:7.2f} s   pin/jflex x{times['pinocchio'] / times['jflex']:.2f}", flush=True)
    return rows


# ---- derivatives (issue 14): jflex's analytic kernels against Pinocchio's, and the batched
# rigid-body kernels against Pinocchio's own multi-threaded batch ---------------------------

DERIV_ALGORITHMS = {
    # name: (jflex per-state function of (q, qd, qdd, tau), Pinocchio per-state call, Pinocchio batch)
    "rnea_derivatives": (lambda r, a, b, c, d: jflex.rnea_derivatives(r, a, b, c),
                         lambda pin, m, x, a, b, c, d: pin.computeRNEADerivatives(m, x, a, b, c), None),
    "aba_derivatives": (lambda r, a, b, c, d: jflex.aba_derivatives(r, a, b, d),
                        lambda pin, m, x, a, b, c, d: pin.computeABADerivatives(m, x, a, b, d), None),
    "rnea": (lambda r, a, b, c, d: jflex.rnea(r, a, b, c),
             lambda pin, m, x, a, b, c, d: pin.rnea(m, x, a, b, c), "rneaInParallel"),
    "aba": (lambda r, a, b, c, d: jflex.aba(r, a, b, d),
            lambda pin, m, x, a, b, c, d: pin.aba(m, x, a, b, d), "abaInParallel"),
}


def pinocchio_batches():
    """Pinocchio's batched entry points in this build (ModelPool + *InParallel), by name."""
    import pinocchio as pin

    return sorted(n for n in dir(pin) if "InParallel" in n or n.endswith("Pool"))


def bench_derivatives(robot, model, batches, algorithms, threads=2, devices=None):
    """Per state: jflex batched (``jflex.batched``; RNEA and ABA as in ``bench_jflex``) against
    Pinocchio called one state at a time in a Python loop and, where this build has one, its
    ``*InParallel`` batch on ``threads`` threads (a ModelPool); with ``devices`` (several CPU
    devices, one core each), jflex's RNEA and ABA batches split over them too, against that
    multi-threaded batch. Results are checked on the first ``CHECK`` states (the parallel batch
    on all of them) before any timing is reported."""
    import pinocchio as pin

    found = pinocchio_batches()
    has_deriv = any("Derivatives" in n for n in found)
    print(f"\nderivatives section; Pinocchio {pin.__version__} batch entry points: {found}"
          + ("" if has_deriv else " (no multi-threaded derivatives batch among them)"), flush=True)
    rng = np.random.default_rng(1)
    rows = []
    data = model.createData()
    for N in batches:
        q = rng.uniform(-1.5, 1.5, (N, robot.nq))
        qd, qdd = rng.normal(size=(2, N, robot.nq))
        tau = np.array([pin.rnea(model, data, q[i], qd[i], qdd[i]) for i in range(N)])
        for name in algorithms:
            jfn, pfn, par = DERIV_ALGORITHMS[name]
            f = lambda a, b, c, d, jfn=jfn: jfn(robot, a, b, c, d)
            # as users call them: rnea and aba through batched's default program (one fused vmap);
            # the derivative kernels in lax.map blocks (program="blocks", 1024 states on CPU: one
            # vmapped program over 1e5 states was 1.6x slower)
            jf = jflex.batched(f, program="blocks") if "derivatives" in name else jflex.batched(f)
            t0 = time.perf_counter()
            out = jax.block_until_ready(jf(q, qd, qdd, tau))
            compile_s = time.perf_counter() - t0
            out = [np.asarray(o) for o in (out if isinstance(out, tuple) else (out,))]
            # copies: Pinocchio returns views of its Data's buffers, overwritten by the next call
            ref = [[np.array(x) for x in (r if isinstance(r, tuple) else (r,))]
                   for r in (pfn(pin, model, data, q[i], qd[i], qdd[i], tau[i]) for i in range(min(N, CHECK)))]
            ref = [np.array([r[k] for r in ref]) for k in range(len(out))]
            diff = max(float(np.abs(o[: len(r)] - r).max() / np.abs(r).max()) for o, r in zip(out, ref))
            if not diff < 1e-9:
                raise SystemExit(f"{name}: jflex differs from Pinocchio by {diff:.1e} at batch {N}; timings would be meaningless")
            jt = best_time(lambda: jax.block_until_ready(jf(q, qd, qdd, tau)))
            pt = best_time(lambda: [pfn(pin, model, data, q[i], qd[i], qdd[i], tau[i]) for i in range(N)], reps=2 if N > 1000 else 3)
            row = {"batch": N, "algorithm": name, "jflex_us": 1e6 * jt / N, "jflex_compile_s": compile_s,
                   "max_rel_diff_vs_pinocchio": diff, "pinocchio_loop_us": 1e6 * pt / N, "pinocchio_parallel_us": None}
            if par is not None and par in found:
                pool = pin.ModelPool(model, threads)
                qT, vT, aT = np.asfortranarray(q.T), np.asfortranarray(qd.T), np.asfortranarray(qdd.T)
                tT = np.asfortranarray(tau.T)
                call = (lambda: getattr(pin, par)(threads, pool, qT, vT, aT)) if par == "rneaInParallel" else (
                    lambda: getattr(pin, par)(threads, pool, qT, vT, tT))
                pres = np.asarray(call()).T
                pdiff = float(np.abs(out[0] - pres).max() / np.abs(pres).max())
                if not pdiff < 1e-9:
                    raise SystemExit(f"{name}: Pinocchio's {par} differs from jflex by {pdiff:.1e}")
                row["pinocchio_parallel_us"] = 1e6 * best_time(call) / N
                row["pinocchio_parallel_threads"] = threads
                if "derivatives" not in name:
                    # jflex.sweep as users call it: NumPy in, NumPy out, one chunk; compiled at its
                    # first call, reused by the later ones
                    sw = lambda: jflex.sweep(f, q, qd, qdd, tau, chunk_size=N, progress=False)
                    sdiff = float(np.abs(sw() - pres).max() / np.abs(pres).max())
                    if not sdiff < 1e-9:
                        raise SystemExit(f"{name}: jflex.sweep differs from Pinocchio's {par} by {sdiff:.1e}")
                    row["jflex_sweep_us"] = 1e6 * best_time(sw) / N
                    row["ratio_pin_parallel_over_jflex_sweep"] = row["pinocchio_parallel_us"] / row["jflex_sweep_us"]
                if devices:
                    jf2 = jflex.batched(f, devices=devices)
                    d2 = float(np.abs(np.asarray(jax.block_until_ready(jf2(q, qd, qdd, tau))) - pres).max() / np.abs(pres).max())
                    if not d2 < 1e-9:
                        raise SystemExit(f"{name}: jflex on {len(devices)} devices differs from Pinocchio's {par} by {d2:.1e}")
                    row["jflex_devices"] = len(devices)
                    row["jflex_devices_us"] = 1e6 * best_time(lambda: jax.block_until_ready(jf2(q, qd, qdd, tau))) / N
                    row["ratio_pin_parallel_over_jflex_devices"] = row["pinocchio_parallel_us"] / row["jflex_devices_us"]
            row["ratio_pin_over_jflex"] = row["pinocchio_loop_us"] / row["jflex_us"]
            row["ratio_pin_parallel_over_jflex"] = (row["pinocchio_parallel_us"] / row["jflex_us"]
                                                    if row["pinocchio_parallel_us"] else None)
            rows.append(row)
            fmt = lambda v, f: "-" if v is None else f.format(v)
            print(f"{N:>7} {name:<17} jflex {row['jflex_us']:8.3f} us  pin loop {row['pinocchio_loop_us']:8.3f} us "
                  f"(x{row['ratio_pin_over_jflex']:.2f})  pin {threads}-thread batch {fmt(row['pinocchio_parallel_us'], '{:8.3f}')} us "
                  f"(x{fmt(row['ratio_pin_parallel_over_jflex'], '{:.2f}')})  compile {compile_s:.1f} s  max rel diff {diff:.1e}"
                  + (f"  | sweep {row['jflex_sweep_us']:8.3f} us (pin batch / sweep x{row['ratio_pin_parallel_over_jflex_sweep']:.2f})"
                     if "jflex_sweep_us" in row else "")
                  + (f"  | jflex on {row['jflex_devices']} CPU devices {row['jflex_devices_us']:8.3f} us "
                     f"(pin {threads}-thread batch / jflex x{row['ratio_pin_parallel_over_jflex_devices']:.2f})"
                     if "jflex_devices_us" in row else ""),
                  flush=True)
    return rows


if __name__ == "__main__":
    main()
