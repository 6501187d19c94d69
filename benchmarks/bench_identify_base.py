"""Base parameters + least-squares identification of an 8-joint torso + arm, end to end, against
Pinocchio's regressor + NumPy/SciPy least squares (issue 18).

Run: ``python benchmarks/bench_identify_base.py [--samples 10000] [--repeat 1] [--out DIR]``.

The robot is TIAGo (example-robot-data, ``tiago_no_hand.urdf``) reduced to the torso lift joint
and the 7 arm joints (wheels and head locked at 0): ``jflex.load_urdf(path, joints=...)`` and
``pin.buildReducedModel``. The parent process draws ``--samples`` random (q, qd, qdd) within the
joint limits, computes the torques with Pinocchio's ``rnea`` plus viscous and Coulomb friction
(``Fv qd + Fc sign(qd)`` per joint) and adds 1 % noise (per joint, of the torque's standard
deviation); both sides read the same arrays and identify the link inertias and the friction (80 +
16 standard parameters; 60 base parameters, as in issue 18's robot log). Each side then runs in a
**fresh process**. The headline is the whole process, from the parent's launch to the answer
(interpreter, imports, URDF, data, identification: what a user waits for); beside it the warm
figure, whose clock starts after the imports and the model load and includes every compilation
(jflex's first calls compile). ``--consistent`` adds a third fresh jflex process that also runs
``physical_fit`` (log-Cholesky, QR-compressed) from the URDF's inertias:

* jflex: ``base_parameters(robot, Regressor())`` (its default random samples),
  ``Regressor.stack`` of all samples, the base columns, ``numpy.linalg.lstsq``.
* Pinocchio: ``computeJointTorqueRegressor`` in a Python loop with the friction columns
  ``diag(qd), diag(sign(qd))`` beside it, stacked; base parameters from
  ``scipy.linalg.qr(W, pivoting=True)`` (rank at 1e-8 of the largest diagonal of R, the first
  ``rank`` pivots); ``numpy.linalg.lstsq`` on those columns.

Checked before the times are printed: the same base-parameter count; the same torque RMSE per
joint (both base sets span the same column space); jflex's observation matrix equal to
Pinocchio's; and the condition number of jflex's base regressor equal to that of Pinocchio's
regressor on the same columns (the pivoted QR's own choice of columns is printed beside it: a
different choice of base columns has a different condition number). The machine may be shared:
the load average is printed; rerun with ``--repeat`` and read the minimum.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np

JOINTS = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))


def tiago_urdf() -> str:
    import importlib.metadata as md

    for f in md.files("example-robot-data") or []:
        if str(f).replace("\\", "/").endswith("robots/tiago_description/robots/tiago_no_hand.urdf"):
            return str(f.locate())
    raise SystemExit("example-robot-data with tiago_no_hand.urdf is needed")


def pin_model(path):
    import pinocchio as pin

    full = pin.buildModelFromUrdf(path)
    lock = [full.getJointId(n) for n in full.names[1:] if n not in JOINTS]
    return pin.buildReducedModel(full, lock, pin.neutral(full))


# one side = one fresh process running one of these; it prints a JSON dict on its last line
_JFLEX = """
import json, sys, time
import numpy as np
import jax, jflex
from jflex import identify as idf
d = np.load(sys.argv[1]); path = sys.argv[2]; joints = sys.argv[3].split(",")
robot = jflex.load_urdf(path, joints=joints)
q, qd, qdd, tau = d["q"], d["qd"], d["qdd"], d["tau"]
t0 = time.perf_counter()
reg = idf.Regressor(viscous=True, coulomb=True)
bp = idf.base_parameters(robot, reg)
t1 = time.perf_counter()
A = np.asarray(reg.stack(robot, q, qd, qdd))
t2 = time.perf_counter()
Ab = A[:, list(bp.independent)]
psi, *_ = np.linalg.lstsq(Ab, tau.ravel(), rcond=None)
t3 = time.perf_counter()
consistent = {}
if sys.argv[6] == "1":  # the physically consistent variant: log-Cholesky fit from the URDF's inertias
    prior = np.concatenate([np.asarray(robot.inertia).ravel(), np.zeros(A.shape[1] - 10 * robot.nq)])
    ph = idf.physical_fit(A, tau.ravel(), robot.nq, prior=prior, prior_weight=1e-4)
    consistent = {"consistent_s": time.perf_counter() - t3, "consistent_steps": ph.steps, "consistent_cost": ph.cost}
whole = time.time() - float(sys.argv[5])  # from the parent's launch: interpreter, imports, loading, work
err = (tau.ravel() - Ab @ psi).reshape(tau.shape)
np.save(sys.argv[4], A)
print(json.dumps({"whole_process_s": whole, **consistent,
                  "total_s": t3 - t0, "base_parameters_s": t1 - t0, "stack_s": t2 - t1, "lstsq_s": t3 - t2,
                  "rank": bp.rank, "independent": list(bp.independent), "cond": float(np.linalg.cond(Ab)),
                  "rmse": np.sqrt(np.mean(err ** 2, axis=0)).tolist(), "joints": list(robot.joint_names)}))
"""

_PIN = """
import json, sys, time
import numpy as np
import pinocchio as pin, scipy.linalg
sys.path.insert(0, sys.argv[5])
from bench_identify_base import pin_model
d = np.load(sys.argv[1])
model = pin_model(sys.argv[2]); data = model.createData()
q, qd, qdd, tau = d["q"], d["qd"], d["qdd"], d["tau"]
t0 = time.perf_counter()
W = np.vstack([np.hstack([pin.computeJointTorqueRegressor(model, data, a, b, c), np.diag(b), np.diag(np.sign(b))])
               for a, b, c in zip(q, qd, qdd)])
t1 = time.perf_counter()
_, R, piv = scipy.linalg.qr(W, mode="economic", pivoting=True)
dg = np.abs(np.diag(R)); r = int(np.sum(dg > 1e-8 * dg[0]))
base = np.sort(piv[:r])
t2 = time.perf_counter()
Wb = W[:, base]
psi, *_ = np.linalg.lstsq(Wb, tau.ravel(), rcond=None)
t3 = time.perf_counter()
whole = time.time() - float(sys.argv[6])  # from the parent's launch: interpreter, imports, loading, work
err = (tau.ravel() - Wb @ psi).reshape(tau.shape)
ind = json.loads(sys.argv[4]) if sys.argv[4] != "-" else None
np.save(sys.argv[3], W)
print(json.dumps({"whole_process_s": whole, "total_s": t3 - t0, "regressor_loop_s": t1 - t0, "qr_s": t2 - t1, "lstsq_s": t3 - t2,
                  "rank": r, "cond": float(np.linalg.cond(Wb)),
                  "cond_on_jflex_columns": float(np.linalg.cond(W[:, ind])) if ind else None,
                  "rmse": np.sqrt(np.mean(err ** 2, axis=0)).tolist(), "joints": list(model.names[1:])}))
"""


def run_snippet(code, *args):
    """Runs ``code`` in a fresh process; ``{launch}`` in ``args`` becomes the launch time (the
    snippet's whole-process clock)."""
    args = [str(time.time()) if x == "{launch}" else x for x in args]
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(out.stderr)
    return json.loads(out.stdout.strip().splitlines()[-1])


def make_data(path, n_samples, seed=0):
    """Random states within the limits; Pinocchio's torques plus friction plus 1 % noise."""
    import pinocchio as pin

    model = pin_model(path)
    data = model.createData()
    rng = np.random.default_rng(seed)
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    q = rng.uniform(lo, hi, size=(n_samples, model.nq))
    qd = rng.uniform(-1.0, 1.0, size=q.shape) * np.minimum(model.velocityLimit, np.pi)
    qdd = rng.uniform(-np.pi, np.pi, size=q.shape)
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd)])
    fv, fc = np.linspace(2.0, 0.5, model.nq), np.linspace(5.0, 1.0, model.nq)  # [N m s/rad], [N m]
    tau = tau + fv * qd + fc * np.sign(qd)
    tau = tau + 0.01 * tau.std(axis=0) * rng.standard_normal(tau.shape)
    return q, qd, qdd, tau


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=1, help="fresh processes per side (minimum reported)")
    ap.add_argument("--consistent", action="store_true", help="also time jflex's physically consistent fit")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    path = tiago_urdf()
    here = str(pathlib.Path(__file__).resolve().parent)
    with tempfile.TemporaryDirectory() as tmp:
        npz = os.path.join(tmp, "data.npz")
        q, qd, qdd, tau = make_data(path, a.samples)
        np.savez(npz, q=q, qd=qd, qdd=qdd, tau=tau)
        load0 = os.getloadavg()[0]
        jf = [run_snippet(_JFLEX, npz, path, ",".join(JOINTS), os.path.join(tmp, "A.npy"), "{launch}", "0")
              for _ in range(a.repeat)]
        ind = json.dumps(jf[0]["independent"])
        pn = [run_snippet(_PIN, npz, path, os.path.join(tmp, "W.npy"), ind, here, "{launch}") for _ in range(a.repeat)]
        jc = ([run_snippet(_JFLEX, npz, path, ",".join(JOINTS), os.path.join(tmp, "A2.npy"), "{launch}", "1")
               for _ in range(a.repeat)] if a.consistent else [])
        load1 = os.getloadavg()[0]
        A, W = np.load(os.path.join(tmp, "A.npy")), np.load(os.path.join(tmp, "W.npy"))
    j, p = min(jf, key=lambda r: r["total_s"]), min(pn, key=lambda r: r["total_s"])
    # the checks: same model, same regressor, same identification
    assert j["joints"] == p["joints"] == list(JOINTS), (j["joints"], p["joints"])
    assert j["rank"] == p["rank"], (j["rank"], p["rank"])
    dA = float(np.abs(A - W).max() / np.abs(W).max())
    assert dA < 1e-9, f"jflex's observation matrix differs from Pinocchio's by {dA:.2e} (relative)"
    assert abs(j["cond"] / p["cond_on_jflex_columns"] - 1) < 1e-6, (j["cond"], p["cond_on_jflex_columns"])
    assert np.allclose(j["rmse"], p["rmse"], rtol=1e-6), (j["rmse"], p["rmse"])
    ratio = j["total_s"] / p["total_s"]
    whole = j["whole_process_s"] / p["whole_process_s"]
    print(f"TIAGo torso + arm, {len(JOINTS)} joints, {a.samples} samples, friction, 1 % torque noise; "
          f"load average {load0:.2f} -> {load1:.2f} on {os.cpu_count()} cores")
    print(f"base parameters: {j['rank']} of {A.shape[1]} (both); observation matrix max rel. difference {dA:.1e}")
    print(f"condition number: jflex's base columns {j['cond']:.4g} (Pinocchio's regressor on them "
          f"{p['cond_on_jflex_columns']:.4g}); pivoted QR's columns {p['cond']:.4g}")
    print("torque RMSE per joint [N, N m]: " + " ".join(f"{x:.4g}" for x in j["rmse"]) + "  (Pinocchio: same to 1e-6)")
    print(f"WHOLE PROCESS (interpreter + imports + URDF + data + identification): jflex {j['whole_process_s']:.2f} s, "
          f"Pinocchio + NumPy {p['whole_process_s']:.2f} s, ratio {whole:.2f}")
    if jc:
        c = min(jc, key=lambda r: r["whole_process_s"])
        print(f"WHOLE PROCESS, physically consistent variant (jflex, + physical_fit on the compressed system): "
              f"{c['whole_process_s']:.2f} s, ratio to Pinocchio + NumPy least squares {c['whole_process_s'] / p['whole_process_s']:.2f} "
              f"(physical_fit {c['consistent_s']:.2f} s, {c['consistent_steps']} steps)")
    print("warm figures (clock after imports and model loading):")
    print(f"jflex     {j['total_s']:8.2f} s  (base_parameters {j['base_parameters_s']:.2f} s, "
          f"stack {j['stack_s']:.2f} s, lstsq {j['lstsq_s']:.2f} s; compilation included)")
    print(f"Pinocchio {p['total_s']:8.2f} s  (regressor loop {p['regressor_loop_s']:.2f} s, "
          f"pivoted QR {p['qr_s']:.2f} s, lstsq {p['lstsq_s']:.2f} s)")
    print(f"ratio jflex / Pinocchio: {ratio:.2f}")
    results = {"jflex": jf, "pinocchio": pn, "jflex_consistent": jc, "ratio": ratio, "ratio_whole_process": whole, "load": [load0, load1], "samples": a.samples,
               "regressor_rel_diff": dA}
    if a.out:
        pathlib.Path(a.out).mkdir(parents=True, exist_ok=True)
        (pathlib.Path(a.out) / "bench_identify_base.json").write_text(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()
