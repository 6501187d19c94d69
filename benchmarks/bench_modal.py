"""Posture sweeps: jflex (jit + vmap through jflex.sweep) against a NumPy/SciPy loop, one process,
same inputs. Not a test: prints a table with throughputs and ratios.

1. Modal analysis of a 3-joint flexible-joint arm (motors held) over N postures: jflex (both
   eigen-solvers, ``solver="newton"`` and ``"eig"``)
   ``modal_analysis`` vs per posture Pinocchio CRBA + gravity derivatives and
   ``scipy.linalg.eig(A, B)`` of seed 003 Eq. 4.13.
2. Tool FRFs (3x3 receptance) over N postures x 512 frequencies: ``jflex.frf_sweep`` (pole-residue
   models in chunks of ``--chunk`` postures, FRFs synthesised in blocks of ``--frf-chunk``), keeping
   only the latest block or storing all; and ``jit(vmap(jflex.frf))`` per ``--frf-chunk`` postures
   (modal with the ``"newton"`` (and ``"eig"``) eigen-solvers; direct), against per posture
   ``numpy.linalg.solve`` over the 512 frequencies and ``J G J^T`` (keeping the latest result or
   storing every result in a preallocated array, to match).

    python benchmarks/bench_modal.py [--modal-n 100000] [--frf-n 10000] [--host-devices 1]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

p = argparse.ArgumentParser()
p.add_argument("--modal-n", type=int, default=100_000)
p.add_argument("--frf-n", type=int, default=10_000)
p.add_argument("--n-freq", type=int, default=512)
p.add_argument("--baseline-n", type=int, default=0, help="postures timed for the SciPy loop (0: all)")
p.add_argument("--host-devices", type=int, default=1, help="CPU devices jflex.sweep shards over")
p.add_argument("--chunk", type=int, default=8192)
p.add_argument("--frf-pole-chunk", type=int, default=4096, help="postures per pole-residue call of frf_sweep")
p.add_argument("--frf-chunk", type=int, default=64, help="postures per FRF call (32 MB outputs per call cost 1.5-2x here)")
p.add_argument("--no-tune-allocator", action="store_true",
               help="leave glibc's malloc thresholds as they are (default: jflex.tune_allocator() for the whole process)")
p.add_argument("--with-eig", action="store_true",
               help="also time solver='eig' (jnp.linalg.eig); on jax 0.10.2 CPU its batched runs stall at random")
args = p.parse_args()
if args.host_devices > 1:
    os.environ["XLA_FLAGS"] = os.environ.get("XLA_FLAGS", "") + f" --xla_force_host_platform_device_count={args.host_devices}"

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import scipy.linalg as sla  # noqa: E402

import jax  # noqa: E402
import jflex  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Staubli TX200 kinematics; plausible link inertias; Table 4.3 joint K and C; rotors r = 196.
inertias = [
    {"mass": 120.0, "com": [0.0, -0.1, -0.2], "inertia": [20.0, 0.0, 18.0, 0.0, 0.0, 12.0]},
    {"mass": 150.0, "com": [0.45, 0.0, 0.05], "inertia": [6.0, 0.0, 40.0, 0.0, 0.0, 42.0]},
    {"mass": 90.0, "com": [0.5, 0.0, 0.0], "inertia": [3.0, 0.0, 25.0, 0.0, 0.0, 26.0]},
]
base = jflex.load_robot(os.path.join(ROOT, "configs", "robots", "staubli_tx200.yaml"))
robot = jflex.from_dh(
    [[0, 0, 0.642, 0], [np.pi / 2, 0.25, 0, 0], [0, 0.95, 0, 0]], tool=[0, 0.994, 0, 0], inertias=inertias
)
assert np.allclose(robot.placement_p, base.placement_p)
K = np.array([1.95e6, 5.63e6, 1.13e6])
C = np.array([3.3e3, 0.3e3, 1.0e3])
r, Im3 = 196.0, 0.0094
Im = np.array([Im3, Im3, Im3])
model = jflex.Model(robot, [jflex.effects.FlexibleJoints(K, C, rotor_inertia=Im, gear_ratio=[r] * 3)])

rng = np.random.default_rng(0)
lo, hi = np.radians([-150, -28, -130]), np.radians([150, 150, 8])


# ---- the NumPy/SciPy reference: Pinocchio for M and dG/dq, SciPy for the eigenproblem --------
pm = pin.Model()
pm.gravity = pin.Motion(np.asarray(robot.gravity), np.zeros(3))
jid = 0
for i in range(3):
    jid = pm.addJoint(jid, pin.JointModelRevoluteUnaligned(np.asarray(robot.axis[i])),
                      pin.SE3(np.asarray(robot.placement_R[i]), np.asarray(robot.placement_p[i])), f"j{i}")
    pm.appendBodyToJoint(jid, pin.Inertia.FromDynamicParameters(np.asarray(robot.inertia[i])), pin.SE3.Identity())
tool_id = pm.addFrame(pin.Frame("tool", jid, 0, pin.SE3(np.asarray(robot.frame_R[-1]), np.asarray(robot.frame_p[-1])),
                                pin.FrameType.OP_FRAME))
pd = pm.createData()
M_rotor = np.zeros((3, 3))
M_rotor[1, 1] = Im3  # rotor 3 rides on link 2 and turns with q2 (the carried term of the effect)


def scipy_matrices(q):
    M0 = pin.crba(pm, pd, q).copy()
    M0 = np.triu(M0) + np.triu(M0, 1).T + M_rotor
    dG = pin.computeGeneralizedGravityDerivatives(pm, pd, q)
    return M0, np.diag(K) + dG, np.diag(C)


def scipy_modal(q):
    M0, K0, C0 = scipy_matrices(q)
    Z = np.zeros((3, 3))
    A = np.block([[C0, M0], [M0, Z]])
    B = np.block([[K0, Z], [Z, -M0]])
    lam, V = sla.eig(-B, A)  # (lambda A + B) v = 0
    keep = np.argsort(-lam.imag)[:3]
    lam, V = lam[keep], V[:3, keep]
    o = np.argsort(np.abs(lam))
    return np.abs(lam[o]) / (2 * np.pi), -lam[o].real / np.abs(lam[o]), V[:, o]


def scipy_frf(q, w):
    M0, K0, C0 = scipy_matrices(q)
    D = K0[None] - w[:, None, None] ** 2 * M0[None] + 1j * w[:, None, None] * C0[None]
    G = np.linalg.solve(D, np.broadcast_to(np.eye(3), D.shape))
    pin.computeJointJacobians(pm, pd, q)
    pin.updateFramePlacements(pm, pd)
    J = pin.getFrameJacobian(pm, pd, tool_id, pin.LOCAL_WORLD_ALIGNED)[:3]
    return J @ G @ J.T


def timed(f):
    t = time.perf_counter()
    out = f()
    jax.block_until_ready(out)
    return out, time.perf_counter() - t


rows = []
# both loops run under the same allocator settings (one process); without them a chunk's outputs
# page-fault afresh on some runs and not others (jflex/_allocator.py)
tuned = False if args.no_tune_allocator else jflex.tune_allocator()
print(f"jax {jax.__version__}, devices {jax.devices()}, jflex.tune_allocator(): {tuned}")

# ---- 1. modal analysis ----------------------------------------------------------------------
N = args.modal_n
chunk = min(args.chunk, N)  # a run with fewer postures than a chunk times one chunk
Q = rng.uniform(lo, hi, (N, 3))
Qj = jax.numpy.asarray(Q)  # postures on the device once (numpy slices per call cost jit ~25 us per posture here)
nb = N if args.baseline_n == 0 else min(N, args.baseline_n)
t0 = time.perf_counter()
ref = [scipy_modal(q) for q in Q[:nb]]
t_s = time.perf_counter() - t0
f_ref = np.array([x[0] for x in ref])
for solver in ("newton", "eig") if args.with_eig else ("newton",):
    fn = lambda q, solver=solver: jflex.modal_analysis(model, q, hold="actuated", solver=solver)
    t0 = time.perf_counter()
    vfn = jax.jit(jax.vmap(fn))
    _ = jax.block_until_ready(vfn(Q[:chunk]).frequency)
    t_compile = time.perf_counter() - t0

    def jflex_modal():
        out = [vfn(Qj[s : s + chunk]) for s in range(0, N - N % chunk, chunk)]
        return [o.frequency for o in out]

    _, t_j = timed(jflex_modal)
    n_j = N - N % chunk
    # the whole N through jflex.sweep: chunked, progress, host copies, its own compile included
    res = {}
    _, t_sweep = timed(lambda: res.setdefault("f", jflex.sweep(fn, Q, chunk_size=chunk, progress=True,
                                                               label=f"jflex.sweep modal ({solver})").frequency))
    f_j = res["f"][:nb]
    err = np.max(np.abs(f_j - f_ref) / f_ref)
    rows.append((f"modal ({solver}), 3-joint flexible, per posture", N, t_s / nb, t_j / n_j, t_sweep / N, err, t_compile))

# ---- 2. tool FRFs ----------------------------------------------------------------------------
N2, nf = args.frf_n, args.n_freq
Q2 = rng.uniform(lo, hi, (N2, 3))
Q2j = jax.numpy.asarray(Q2)
w = 2 * np.pi * np.linspace(0.5, 60.0, nf)
ch2 = args.frf_chunk  # postures per call: 64 x 512 x 9 complex outputs (4.7 MB) stay cache- and allocator-friendly
nb2 = N2 if args.baseline_n == 0 else min(N2, args.baseline_n)

# the SciPy loop twice: keeping only its latest result (as the jflex loops with `consume` do), and
# storing every result in a preallocated array (as frf_sweep's returned array does)
t0 = time.perf_counter()
for q in Q2[:nb2]:
    G_last = scipy_frf(q, w)
t_keep = (time.perf_counter() - t0) / nb2
G_all = np.empty((nb2, nf, 3, 3), complex)
t0 = time.perf_counter()
for i, q in enumerate(Q2[:nb2]):
    G_all[i] = scipy_frf(q, w)
t_store = (time.perf_counter() - t0) / nb2
Gref = G_all[:ch2]


def rel_err(Gj):
    return max(np.max(np.abs(Gj[i] - Gref[i])) / np.max(np.abs(Gref[i])) for i in range(min(ch2, nb2)))


# (a) jflex.frf_sweep: PoleResidue models ~args.frf_pole_chunk postures per call, FRFs ch2 per call
sweep_kw = dict(hold="actuated", frame="tool", chunk_size=args.frf_pole_chunk, block_size=ch2, progress=False)
t0 = time.perf_counter()
jflex.frf_sweep(model, Q2j, w, consume=lambda s, H: None, **sweep_kw)  # compiles its chunk and block shapes
t_compile = time.perf_counter() - t0
keep = {}
_, t_j = timed(lambda: jflex.frf_sweep(model, Q2j, w, consume=lambda s, H: keep.__setitem__("H", H), **sweep_kw))
rows.append((f"tool FRF 3x3 x {nf} (frf_sweep, keep latest)", N2, t_keep, t_j / N2, float("nan"),
             rel_err(jflex.frf_sweep(model, Q2[:ch2], w, **sweep_kw)), t_compile))
res = {}
_, t_j = timed(lambda: res.setdefault("H", jflex.frf_sweep(model, Q2j, w, **sweep_kw)))
rows.append((f"tool FRF 3x3 x {nf} (frf_sweep, store all)", N2, t_store, t_j / N2, float("nan"), rel_err(res.pop("H")), 0.0))

# (b) one program per chunk of ch2 postures: jit(vmap(jflex.frf))
for method, solver in (("modal", "newton"), ("modal", "eig"), ("direct", "eig")) if args.with_eig else (("modal", "newton"), ("direct", "eig")):
    g = jax.jit(jax.vmap(lambda q: jflex.frf(model, q, w, hold="actuated", frame="tool", method=method, solver=solver)))
    t0 = time.perf_counter()
    jax.block_until_ready(g(Q2[:ch2]))
    t_compile = time.perf_counter() - t0

    def run():
        out = None
        for s in range(0, N2 - N2 % ch2, ch2):
            out = g(Q2j[s : s + ch2])
            out = np.asarray(out)  # to host, like a sweep keeping its results
        return out

    _, t_j = timed(run)
    n_j = N2 - N2 % ch2
    rows.append((f"tool FRF 3x3 x {nf} (jit(vmap(frf)) {method}, {solver})", N2, t_keep, t_j / n_j, float("nan"),
                 rel_err(np.asarray(g(Q2[:ch2]))), t_compile))

print()
print(f"{'case':48s} {'N':>7s} {'SciPy us':>10s} {'jflex us':>10s} {'ratio':>7s} {'sweep us':>9s} {'max rel diff':>12s} {'compile s':>9s}")
for name, n, ts, tj, tsw, e, tc in rows:
    print(f"{name:48s} {n:7d} {1e6 * ts:10.2f} {1e6 * tj:10.2f} {ts / tj:7.1f} {1e6 * tsw:9.2f} {e:12.2e} {tc:9.1f}")
print("\nratio = SciPy-loop time / jflex time per posture (jit+vmap in chunks, compile excluded);"
      " 'sweep us' is jflex.sweep end to end (progress, host copies, one compile included).")
