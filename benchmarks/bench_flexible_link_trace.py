"""What a first call on a model with assumed-mode flexible links costs before it runs: the
operations in its forward-dynamics program, the time to trace it, and to trace and compile it.

Run: ``python benchmarks/bench_flexible_link_trace.py [--against DIR]``.

Two models: a rotor carrying one flexible link (2 modes, Kelvin-Voigt damping) and a sliding
link (2 modes) through a flexible hub (1 mode), both with foreshortening of the sliding one. No
other open library has flexible links with foreshortening, so the peer is another jflex source
tree: ``--against DIR`` measures that tree too (each in a fresh process) and prints the ratios,
e.g. a checkout of an earlier commit (``git worktree add /tmp/old <rev>``).
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys

_CHILD = r"""
import json, time
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
import jflex
from jflex.effects import FlexibleLink, KelvinVoigt


def rod(mu, a, b):
    m, Izz = mu * (b - a), mu * (b**3 - a**3) / 3
    return [m, m * (a + b) / 2, 0, 0, 1e-6, 0, Izz, 0, 0, Izz]


def count(j):
    c = 0
    for e in j.eqns:
        c += 1
        for p in e.params.values():
            if hasattr(p, "jaxpr"):
                c += count(p.jaxpr if hasattr(p.jaxpr, "eqns") else p.jaxpr.jaxpr)
    return c


rotor = jflex.make_robot(joint_names=["hub"], link_names=["hub"], parents=[-1], joint_types=["revolute"],
                         placement_R=np.eye(3)[None], placement_p=np.zeros((1, 3)), axis=[[0, 0, 1.0]],
                         inertia=np.array([[0.02, 0, 0, 0, 0.02, 0, 0.02, 0, 0, 0.02]]), gravity=(0, 0, 0))
carrier = jflex.make_robot(
    joint_names=["rev", "pri"], link_names=["hub", "link"], parents=[-1, 0], joint_types=["revolute", "prismatic"],
    placement_R=np.stack([np.eye(3)] * 2), placement_p=np.zeros((2, 3)), axis=[[0, 0, 1.0], [1.0, 0, 0]],
    inertia=np.array([rod(2.1424, 0.0, 0.7), rod(0.785, 0.365, 1.065)]), gravity=(0, 0, 0))
models = {
    "rotor + flexible link": jflex.Model(rotor, [FlexibleLink("hub", jflex.make_beam(0.8, 0.157, 0.349, 2),
                                                              damping=KelvinVoigt(2e-3))]),
    "sliding link on a flexible hub": jflex.Model(carrier, [FlexibleLink(
        "hub", jflex.make_beam(0.365, 0.785, 6.33, 2), sliding_joint="pri", hub=jflex.make_beam(0.7, 2.1424, 3000.0, 1),
        include_rigid=False, name="arm", foreshortening=True)]),
}
out = {}
for name, m in models.items():
    x, xd = jnp.full(m.nx, 0.01), jnp.full(m.nx, 0.1)

    def fd(model, x, xd):
        return jflex.model_forward_dynamics(model, 0.0, x, xd, jnp.zeros(model.nz), jnp.zeros(model.robot.nq))[0]

    t = time.perf_counter(); jp = jax.make_jaxpr(fd)(m, x, xd); tt = time.perf_counter() - t
    t = time.perf_counter(); jax.jit(fd).lower(m, x, xd).compile(); tc = time.perf_counter() - t
    out[name] = dict(operations=count(jp.jaxpr), trace_s=tt, trace_compile_s=tc)
print(json.dumps(out))
"""


def measure(src: str) -> dict:
    src = str(pathlib.Path(src).resolve())
    env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    # run in the tree itself: ``python -c`` puts the working folder first on the path
    res = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, env=env, check=True, cwd=src)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None):
    p = argparse.ArgumentParser(prog="bench_flexible_link_trace")
    p.add_argument("--against", default=None, help="another jflex source tree to measure beside this one")
    a = p.parse_args(argv)
    here = measure(str(pathlib.Path(__file__).resolve().parents[1]))
    other = measure(a.against) if a.against else None
    print("| model | operations | trace [s] | trace + compile [s] |" + (" against: ops / trace / trace+compile |" if other else ""))
    print("|---|---|---|---|" + ("---|" if other else ""))
    for name, r in here.items():
        row = f"| {name} | {r['operations']} | {r['trace_s']:.2f} | {r['trace_compile_s']:.2f} |"
        if other:
            o = other[name]
            row += (f" {o['operations']} / {o['trace_s']:.2f} / {o['trace_compile_s']:.2f} "
                    f"(x {o['operations'] / r['operations']:.2f} / {o['trace_s'] / r['trace_s']:.2f} / "
                    f"{o['trace_compile_s'] / r['trace_compile_s']:.2f}) |")
        print(row)


if __name__ == "__main__":
    main()
