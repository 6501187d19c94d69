"""jflex on an accelerator (GPU), against MuJoCo MJX on the same device when it is installed.

Run: ``python benchmarks/bench_gpu.py [--size full|tiny] [--robot panda|planar2] [--out DIR]``.

For each dtype (float64, float32) and batch (``full``: 1e3, 1e4, 1e5, 1e6 states): ``rnea``,
``crba``, ``aba``, ``rnea_derivatives`` and ``aba_derivatives`` through ``jflex.batched`` (its
default program and ``program="blocks"`` with the backend's default block size), MJX's inverse
and forward dynamics where installed; then modal analysis and FRF sweeps of the robot with a
flexible joint at every joint, with each solver (``eig``, ``newton``). Every timed result is first
checked: the rigid-body kernels against Pinocchio on the CPU (first 32 states), modal frequencies
against SciPy's ``eig`` of the same linearisation, FRFs of the modal method against the direct
method. A solver missing on the device is reported with the error it raised, not hidden.

It also lists, per kernel, the host callbacks left inside the compiled program (custom calls
to the Python runtime): each one means the device hands control back to the host.

A machine without Pinocchio (a lent GPU) checks against a reference file written on one that has it:
``python benchmarks/bench_gpu.py --write-reference ref.npz`` (same ``--size``/``--robot``) here, then
``--reference ref.npz`` there; the file holds the robot's URDF text, the checked states and
Pinocchio's values for them. Each result row is written to ``--out`` as soon as it is measured
(``bench_gpu_<dtype>.json``), so a run stopped by its time limit keeps what it measured;
``--budget-s`` stops starting new measurements after that many seconds (per dtype: its share),
and names what it skipped.

``--size tiny`` (a test runs it on CPU): batch 8, the 2-joint ``planar2`` arm, one posture grid
of 3 postures and 8 frequencies. The first line printed names the device.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import re
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

import jflex

PLANAR2 = """<robot name="planar2">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.25 0 0"/><mass value="2.0"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.2 0 0.01"/><mass value="1.0"/>
    <inertia ixx="0.005" ixy="0.001" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="100" velocity="5"/></joint>
</robot>"""

CHECK = 32
KERNELS = {
    "rnea": (lambda r, q, v, a, t: jflex.rnea(r, q, v, a), lambda pin, m, d, q, v, a, t: pin.rnea(m, d, q, v, a)),
    "crba": (lambda r, q, v, a, t: jflex.crba(r, q), lambda pin, m, d, q, v, a, t: _sym(pin.crba(m, d, q))),
    "aba": (lambda r, q, v, a, t: jflex.aba(r, q, v, t), lambda pin, m, d, q, v, a, t: pin.aba(m, d, q, v, t)),
    "rnea_derivatives": (lambda r, q, v, a, t: jflex.rnea_derivatives(r, q, v, a),
                         lambda pin, m, d, q, v, a, t: pin.computeRNEADerivatives(m, d, q, v, a)),
    "aba_derivatives": (lambda r, q, v, a, t: jflex.aba_derivatives(r, q, v, t),
                        lambda pin, m, d, q, v, a, t: pin.computeABADerivatives(m, d, q, v, t)),
}


def _copy(r):
    return tuple(np.array(x, copy=True) for x in r) if isinstance(r, tuple) else np.array(r, copy=True)


def _sym(M):
    M = np.array(M)
    return np.triu(M) + np.triu(M, 1).T


def load(name, reference=None):
    """(jflex robot, Pinocchio model or None, URDF text) of the same arm; with a reference file
    (written by ``--write-reference``), the URDF comes from it and Pinocchio is not needed."""
    if reference is not None:
        text = str(reference["urdf"])
        return jflex.from_urdf_string(text, name=str(reference["robot"])), None, text
    import pinocchio as pin

    if name == "planar2":
        return jflex.from_urdf_string(PLANAR2, name="planar2"), pin.buildModelFromXML(PLANAR2), PLANAR2
    from jflex._config import _example_robot_urdf

    path = str(_example_robot_urdf("panda"))
    text = pathlib.Path(path).read_text()
    for j in ("panda_finger_joint1", "panda_finger_joint2"):
        i = text.index(f'name="{j}"')
        k = text.index('type="prismatic"', i)
        text = text[:k] + 'type="fixed"' + text[k + len('type="prismatic"'):]
    full = pin.buildModelFromUrdf(path)
    lock = [full.getJointId("panda_finger_joint1"), full.getJointId("panda_finger_joint2")]
    return jflex.from_urdf_string(text, name="panda7"), pin.buildReducedModel(full, lock, pin.neutral(full)), text


def cast(tree, dtype):
    return jax.tree_util.tree_map(lambda x: x.astype(dtype) if eqx_float(x) else x, tree)


def eqx_float(x):
    return isinstance(x, (jax.Array, np.ndarray)) and jnp.issubdtype(x.dtype, jnp.floating)


def timed(fn, reps=3):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    best = np.inf
    for _ in range(reps):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        best = min(best, time.perf_counter() - t0)
    return out, first, best


def callbacks(jitted, *args):
    """Custom-call targets of the compiled program that call back into Python."""
    try:
        txt = jitted.lower(*args).compile().as_text()
    except Exception as exc:  # a program that cannot be lowered separately (sharded wrapper)
        return [f"? ({type(exc).__name__})"]
    return sorted({t for t in re.findall(r'custom_call_target="([^"]+)"', txt) if "callback" in t or "python" in t})


def states(N, nq, seed=0):
    """The batch of states timed at size N (the first CHECK are those checked)."""
    rng = np.random.default_rng(seed + N)
    q = rng.uniform(-1.5, 1.5, (N, nq))
    v, a, t = rng.normal(size=(3, N, nq))
    return q, v, a, 20.0 * t


def pinocchio_reference(robot_name, batches, kernels):
    """Pinocchio's values for the first CHECK states of every batch: what ``--reference`` reads."""
    import pinocchio as pin

    robot, model, urdf = load(robot_name)
    data = model.createData()
    ref = {"urdf": np.array(urdf), "robot": np.array(robot_name)}
    xml = pin.buildModelFromXML(urdf)  # the model MJX is compared with (its own URDF import)
    xd = xml.createData()
    for N in batches:
        q, v, a, t = (x[:CHECK] for x in states(N, robot.nq))
        for name in kernels:
            out = [_copy(KERNELS[name][1](pin, model, data, q[i], v[i], a[i], t[i])) for i in range(len(q))]
            for k in range(len(out[0]) if isinstance(out[0], tuple) else 1):
                ref[f"{N}/{name}/{k}"] = np.array([np.array(o[k] if isinstance(o, tuple) else o) for o in out])
        ref[f"{N}/mjx/rnea"] = np.array([pin.rnea(xml, xd, q[i], v[i], a[i]) for i in range(len(q))])
        ref[f"{N}/mjx/aba"] = np.array([pin.aba(xml, xd, q[i], v[i], t[i]) for i in range(len(q))])
    return ref


def reference_of(ref, N, name):
    parts = []
    while f"{N}/{name}/{len(parts)}" in ref:
        parts.append(np.asarray(ref[f"{N}/{name}/{len(parts)}"]))
    if not parts:
        raise SystemExit(f"the reference file has no Pinocchio values for {name} at batch {N}: write it with the "
                         "same --size, --robot and --kernels")
    return parts


class Budget:
    """Stops new measurements once ``seconds`` have passed; what was skipped is recorded."""

    def __init__(self, seconds):
        self.t0, self.seconds = time.perf_counter(), seconds

    def left(self):
        return self.seconds is None or time.perf_counter() - self.t0 < self.seconds


def rigid(robot, ref, urdf, batches, dtypes, programs, kernels, rows, budget, record):
    for N in batches:
        q, v, a, t = states(N, robot.nq)
        for dtype in dtypes:
            r = cast(robot, dtype)
            args = [jnp.asarray(x, dtype) for x in (q, v, a, t)]
            tol = 1e-9 if dtype == "float64" else 2e-3
            for name in kernels:
                jfn, _ = KERNELS[name]
                R_all = reference_of(ref, N, name)
                f = lambda q, v, a, t, jfn=jfn, r=r: jfn(r, q, v, a, t)
                for program in programs(N):
                    row = {"batch": N, "dtype": dtype, "kernel": name, "program": program}
                    if not budget.left():
                        record(dict(row, skipped="time budget spent"))
                        continue
                    jf = jflex.batched(f, program=program)
                    try:
                        out, first, best = timed(lambda: jf(*args))
                    except Exception as exc:
                        row["error"] = f"{type(exc).__name__}: {str(exc)[:200]}"
                        record(row)
                        print(f"{N:>8} {dtype} {name:<17} {program:<7} FAILED {row['error']}", flush=True)
                        continue
                    outs = out if isinstance(out, tuple) else (out,)
                    diff = max(float(np.abs(np.asarray(o[: len(R)], float) - R).max() / max(np.abs(R).max(), 1e-300))
                               for o, R in zip(outs, R_all))
                    flagged = getattr(jf, "_flagged", None)
                    row.update(us_per_state=1e6 * best / N, first_call_s=first, max_rel_diff_vs_pinocchio=diff,
                               ok=bool(diff < tol), out_dtype=str(outs[0].dtype),
                               host_callbacks=callbacks(flagged, *args) if flagged else ["? (not a flagged program)"],
                               host_callbacks_plain_jit_vmap=callbacks(jax.jit(jax.vmap(f)), *[x[:1] for x in args]))
                    record(row)
                    print(f"{N:>8} {dtype} {name:<17} {program:<7} {row['us_per_state']:10.4f} us/state  first call "
                          f"{first:6.2f} s  rel diff {diff:.1e}{'' if row['ok'] else ' WRONG'}  callbacks "
                          f"{row['host_callbacks']} (plain jit(vmap): {row['host_callbacks_plain_jit_vmap']})",
                          flush=True)
            if budget.left():
                mjx_rows(urdf, ref, q, v, a, t, N, dtype, record)


def mjx_rows(urdf, ref, q, v, a, t, N, dtype, record):
    """MuJoCo MJX inverse and forward dynamics on the same device, checked like jflex's."""
    try:
        import mujoco
        from mujoco import mjx
    except ImportError:
        return
    try:
        text = re.sub(r"<(visual|collision)>.*?</\1>", "", urdf, flags=re.S)
        m = mujoco.MjModel.from_xml_string(text)
        m.opt.gravity[:] = (0, 0, -9.81)
        # RNEA/ABA as Pinocchio and jflex compute them: no joint-limit constraints (random states
        # lie beyond the Panda's limits), no damping, armature or dry friction from the URDF import
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
        m.dof_damping[:] = 0.0
        m.dof_armature[:] = 0.0
        m.dof_frictionloss[:] = 0.0
        mx = mjx.put_model(m)
        nv = m.nv
        pad = lambda x: jnp.asarray(np.concatenate([x, np.zeros((N, nv - x.shape[1]))], axis=1), dtype)

        def inv(qq, vv, aa):
            d = mjx.make_data(mx).replace(qpos=qq, qvel=vv, qacc=aa)
            return mjx.inverse(mx, d).qfrc_inverse

        def fwd(qq, vv, tt):
            d = mjx.make_data(mx).replace(qpos=qq, qvel=vv, qfrc_applied=tt)
            return mjx.forward(mx, d).qacc

        n = q.shape[1]
        for name, f, xs in (("rnea", inv, (q, v, a)), ("aba", fwd, (q, v, t))):
            jf = jax.jit(jax.vmap(f))
            args = [pad(x) for x in xs]
            out, first, best = timed(lambda: jf(*args))
            row = {"batch": N, "dtype": dtype, "kernel": name, "program": "mjx", "us_per_state": 1e6 * best / N,
                   "first_call_s": first, "mujoco": mujoco.__version__}
            R = np.asarray(ref[f"{N}/mjx/{name}"])
            row["max_rel_diff_vs_pinocchio"] = float(np.abs(np.asarray(out)[: len(R), :n] - R).max() / np.abs(R).max())
            row["ok"] = bool(row["max_rel_diff_vs_pinocchio"] < (1e-9 if dtype == "float64" else 2e-3))
            record(row)
            print(f"{N:>8} {dtype} {name:<17} mjx     {row['us_per_state']:10.4f} us/state  first call {first:6.2f} s  "
                  f"rel diff {row['max_rel_diff_vs_pinocchio']:.1e}",
                  flush=True)
    except Exception as exc:  # a peer that fails on this robot is reported, not fatal
        print(f"  mjx: skipped ({type(exc).__name__}: {str(exc)[:160]})", flush=True)


def flexible(robot):
    n = robot.nq
    return jflex.Model(robot, [jflex.effects.FlexibleJoints(jnp.full(n, 1e4), jnp.full(n, 5.0), jnp.full(n, 0.1),
                                                             jnp.full(n, 50.0))])


def modal_and_frf(robot, n_postures, n_freq, rows, budget, record):
    import scipy.linalg

    model = flexible(robot)
    rng = np.random.default_rng(3)
    Q = rng.uniform(-1.0, 1.0, (n_postures, robot.nq))
    freqs = {}
    for solver in ("eig", "newton"):
        f = jax.jit(jax.vmap(lambda q, s=solver: jflex.modal_analysis(model, q, hold="actuated", solver=s).frequency))
        row = {"kernel": "modal_analysis", "solver": solver, "batch": n_postures, "dtype": str(jnp.asarray(1.0).dtype)}
        if not budget.left():
            record(dict(row, skipped="time budget spent"))
            continue
        try:
            out, first, best = timed(lambda: f(jnp.asarray(Q)), reps=2)
        except Exception as exc:
            row["error"] = f"{type(exc).__name__}: {str(exc)[:300]}"
            print(f"modal {solver}: FAILED on {jax.default_backend()}: {row['error']}", flush=True)
            record(row)
            continue
        freqs[solver] = np.asarray(out)
        row.update(us_per_posture=1e6 * best / n_postures, first_call_s=first)
        record(row)
        print(f"modal {solver:<6} {n_postures} postures: {row['us_per_posture']:10.1f} us/posture, first call {first:.2f} s",
              flush=True)
    # reference: SciPy's eig of the same linearisation (first postures, on the host)
    k = min(n_postures, 3)
    ref = []
    for i in range(k):
        _, lin = jflex.linear.linearization(model, jnp.asarray(Q[i]), hold="actuated")
        M, C, K = (np.asarray(x) for x in (lin.M, lin.C, lin.K))
        n = M.shape[0]
        lam = scipy.linalg.eigvals(np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]]))
        ref.append(np.sort(np.abs(lam[lam.imag > 0])) / (2 * np.pi))
    if freqs:
        m = min(len(r) for r in ref)
        ref = [r[:m] for r in ref]
    for solver, F in freqs.items():
        F = np.sort(F[:k], axis=1)[:, : len(ref[0])]
        diff = float(np.abs(F - np.array(ref)[:, : F.shape[1]]).max() / np.abs(ref).max())
        for row in rows:
            if row.get("kernel") == "modal_analysis" and row.get("solver") == solver:
                row["max_rel_diff_vs_scipy_eig"] = diff
                row["ok"] = bool(diff < (1e-6 if jax.config.jax_enable_x64 else 1e-3))
        print(f"modal {solver}: max relative difference from SciPy eig {diff:.1e}", flush=True)
    record(None)  # the rows above now carry their check

    omega = jnp.linspace(2 * np.pi * 1.0, 2 * np.pi * 200.0, n_freq)
    direct = None
    for solver in ("eig", "newton"):
        row = {"kernel": "frf_sweep", "solver": solver, "batch": n_postures, "frequencies": n_freq,
               "dtype": str(jnp.asarray(1.0).dtype)}
        if not budget.left():
            record(dict(row, skipped="time budget spent"))
            continue
        try:
            out, first, best = timed(lambda s=solver: jflex.frf_sweep(model, Q, omega, hold="actuated", solver=s,
                                                                         progress=False), reps=1)
        except Exception as exc:
            row["error"] = f"{type(exc).__name__}: {str(exc)[:300]}"
            print(f"frf_sweep {solver}: FAILED on {jax.default_backend()}: {row['error']}", flush=True)
            record(row)
            continue
        if direct is None:
            direct = np.asarray(jflex.frf_sweep(model, Q[:2], omega, hold="actuated", method="direct", progress=False))
        row["max_rel_diff_vs_direct"] = float(np.abs(np.asarray(out)[:2] - direct).max() / np.abs(direct).max())
        row["ok"] = bool(row["max_rel_diff_vs_direct"] < (1e-6 if jax.config.jax_enable_x64 else 1e-3))
        row.update(us_per_posture=1e6 * best / n_postures, first_call_s=first)
        record(row)
        print(f"frf_sweep {solver:<6} {n_postures} postures x {n_freq} frequencies: {row['us_per_posture']:10.1f} us/posture, "
              f"first call {first:.2f} s, rel diff from the direct method {row['max_rel_diff_vs_direct']:.1e}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", choices=["full", "tiny"], default="full")
    ap.add_argument("--robot", choices=["panda", "planar2"], default=None, help="default: panda (full), planar2 (tiny)")
    ap.add_argument("--dtypes", nargs="+", default=["float64", "float32"])
    ap.add_argument("--kernels", nargs="+", default=list(KERNELS), choices=list(KERNELS))
    ap.add_argument("--batches", nargs="+", type=int, default=None, help="default: 1e3 1e4 1e5 1e6 (full), 8 (tiny)")
    ap.add_argument("--postures", type=int, default=None, help="modal/FRF postures (default 1000 full, 3 tiny)")
    ap.add_argument("--frequencies", type=int, default=None, help="FRF frequencies (default 200 full, 8 tiny)")
    ap.add_argument("--no-modal", action="store_true", help="rigid-body kernels (and MJX) only")
    ap.add_argument("--out", default=None)
    ap.add_argument("--reference", default=None, help="Pinocchio values from --write-reference (no Pinocchio needed)")
    ap.add_argument("--write-reference", default=None, metavar="FILE")
    ap.add_argument("--budget-s", type=float, default=None, help="start no new measurement after this (all dtypes)")
    args = ap.parse_args(argv)
    tiny = args.size == "tiny"
    robot_name = args.robot or ("planar2" if tiny else "panda")
    batches = args.batches or ([8] if tiny else [1000, 10000, 100000, 1000000])
    if args.write_reference:
        np.savez_compressed(args.write_reference, **pinocchio_reference(robot_name, batches, args.kernels))
        print(f"wrote {args.write_reference}: Pinocchio values for {robot_name}, batches {batches}, {args.kernels}")
        return []
    x64 = bool(jax.config.jax_enable_x64)
    if len(args.dtypes) > 1 or (args.dtypes[0] == "float32") == x64:
        # one fresh process per dtype: float32 is jflex with JFLEX_X64=0 (with x64 on, float32 inputs
        # are promoted to float64 inside the kernels), read before JAX starts
        import os
        import subprocess
        import tempfile

        rows, part, failed = [], {}, 0
        t0 = time.perf_counter()
        for k, dtype in enumerate(args.dtypes):
            with tempfile.TemporaryDirectory() as tmp:
                out_dir = args.out or tmp
                argv2 = [a for a in (argv if argv is not None else sys.argv[1:])]
                cut = [i for i, a in enumerate(argv2) if a in ("--dtypes", "--out", "--budget-s")]
                for i in sorted(cut, reverse=True):  # drop --dtypes/--out/--budget-s and their values
                    j = i + 1
                    while j < len(argv2) and not argv2[j].startswith("--"):
                        j += 1
                    del argv2[i:j]
                if args.budget_s is not None:  # this dtype's share of what is left
                    share = (args.budget_s - (time.perf_counter() - t0)) / (len(args.dtypes) - k)
                    argv2 += ["--budget-s", str(max(share, 0.0))]
                env = dict(os.environ, JFLEX_X64="1" if dtype == "float64" else "0")
                res = subprocess.run([sys.executable, __file__, *argv2, "--dtypes", dtype, "--out", out_dir], env=env)
                failed += res.returncode != 0
                path = pathlib.Path(out_dir) / f"bench_gpu_{dtype}.json"
                if path.exists():
                    part = json.loads(path.read_text())
                    rows += part["rows"]
        if args.out:
            pathlib.Path(args.out).mkdir(parents=True, exist_ok=True)
            (pathlib.Path(args.out) / "bench_gpu.json").write_text(json.dumps(dict(part, rows=rows), indent=1))
        if failed:
            sys.exit(f"{failed} of the dtype runs failed (their rows so far are kept in {args.out or 'the output'})")
        return rows
    dev = jax.devices()[0]
    print(f"device: {getattr(dev, 'device_kind', dev.platform)} ({jax.default_backend()}), jax {jax.__version__}, "
          f"robot {robot_name}, size {args.size}", flush=True)
    ref = dict(np.load(args.reference)) if args.reference else pinocchio_reference(robot_name, batches, args.kernels)
    robot, _, urdf = load(robot_name, ref)
    rows = []
    head = {"device": str(getattr(dev, "device_kind", dev.platform)), "backend": jax.default_backend(),
            "jax": jax.__version__, "robot": robot_name, "size": args.size}

    def record(row):
        if row is not None:
            rows.append(row)
        if args.out:  # after every row: a run stopped by its time limit keeps what it measured
            pathlib.Path(args.out).mkdir(parents=True, exist_ok=True)
            (pathlib.Path(args.out) / f"bench_gpu_{args.dtypes[0]}.json").write_text(json.dumps(dict(head, rows=rows), indent=1))
            (pathlib.Path(args.out) / "bench_gpu.json").write_text(json.dumps(dict(head, rows=rows), indent=1))

    budget = Budget(args.budget_s)
    from jflex._sweep import default_batch_size

    block = default_batch_size()
    # lax.map blocks differ from one fused vmap only when the batch holds several blocks
    programs = (lambda N: ["vmap"]) if tiny else (lambda N: ["vmap", "blocks"] if N >= 2 * block else ["vmap"])
    if not args.no_modal:
        modal_and_frf(robot, args.postures or (3 if tiny else 1000), args.frequencies or (8 if tiny else 200), rows,
                      budget, record)
    rigid(robot, ref, urdf, batches, args.dtypes, programs, args.kernels, rows, budget, record)
    bad = [r for r in rows if r.get("ok") is False]
    if bad:
        sys.exit(f"{len(bad)} results differ from their references (Pinocchio, SciPy eig, direct FRF): "
                 "timings of a wrong program are no timings")
    return rows


if __name__ == "__main__":
    main()
