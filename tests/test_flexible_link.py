"""Assumed-mode flexible links: frequencies against closed forms and FE, energy conservation of
the nonlinear equations (fixed and sliding links, flexible hub), exact dissipation of Kelvin-Voigt
damping, and outputs."""

import pytest

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg as sl

import jflex
from jflex.effects import FlexibleLink, KelvinVoigt
from _sim_helpers import rotor
from test_beam import _fe_frequencies

MU, L, EI = 0.157, 0.8, 0.349


def _eig(lin):
    w2 = sl.eigh(np.asarray(lin.K), np.asarray(lin.M), eigvals_only=True)
    return np.sqrt(np.clip(w2, 0, None))


def _fe_hub(L, m, EI, Ih, ne=60, k=3):
    """FE beam whose root rotation is free and carries the hub inertia ``Ih`` (pinned hub)."""
    h = L / ne
    ke = EI / h**3 * np.array([[12, 6 * h, -12, 6 * h], [6 * h, 4 * h * h, -6 * h, 2 * h * h],
                               [-12, -6 * h, 12, -6 * h], [6 * h, 2 * h * h, -6 * h, 4 * h * h]])
    me = m * h / 420 * np.array([[156, 22 * h, 54, -13 * h], [22 * h, 4 * h * h, 13 * h, -3 * h * h],
                                 [54, 13 * h, 156, -22 * h], [-13 * h, -3 * h * h, -22 * h, 4 * h * h]])
    n = 2 * (ne + 1)
    K, M = np.zeros((n, n)), np.zeros((n, n))
    for e in range(ne):
        i = slice(2 * e, 2 * e + 4)
        K[i, i] += ke
        M[i, i] += me
    M[1, 1] += Ih
    w2 = sl.eigh(K[1:, 1:], M[1:, 1:], eigvals_only=True)
    return np.sqrt(np.clip(w2, 0, None))[1:k + 1]


def test_clamped_and_pinned_frequencies():
    Ih = 0.02
    model = jflex.Model(rotor(Ih), [FlexibleLink("hub", jflex.make_beam(L, MU, EI, 5))])
    x0 = jnp.zeros(model.nx)
    # jit: eager op-by-op linearisation of the quadrature Lagrangian is slow to dispatch
    lin = eqx.filter_jit(jflex.linearize)
    clamped = _eig(lin(model, x0, hold=("j1",)))
    np.testing.assert_allclose(clamped[:3], _fe_frequencies(L, MU, EI, k=3), rtol=1e-3)
    pinned = _eig(lin(model, x0))[1:3]  # [0] is the rigid rotation
    np.testing.assert_allclose(pinned, _fe_hub(L, MU, EI, Ih, k=2), rtol=5e-3)


def _spin_model(k_e):
    beam = jflex.make_beam(L, MU, EI, 2)
    return jflex.Model(rotor(0.02), [FlexibleLink("hub", beam, damping=KelvinVoigt(k_e), thickness=0.002)])


def test_energy_conserved_and_kelvin_voigt_dissipation_exact():
    period = 2 * np.pi / float(jflex.clamped_free_frequencies(jflex.make_beam(L, MU, EI, 1))[0])
    ts = jnp.linspace(0, 10 * period, 1001)
    x0, xd0 = jnp.array([0.0, 0.02, -0.002]), jnp.array([1.5, 0.0, 0.0])
    outs = ("energy", "work", "xd")
    r0 = jflex.simulate(_spin_model(0.0), ts, x0, xd0, rtol=1e-12, atol=1e-14, outputs=outs)
    E = np.asarray(r0["energy"])
    assert np.max(np.abs(E - E[0])) / E[0] < 1e-8
    k_e = 2e-3
    r = jflex.simulate(_spin_model(k_e), ts, x0, xd0, rtol=1e-11, atol=1e-13, outputs=outs)
    E, W, xd = np.asarray(r["energy"]), np.asarray(r["work"]), np.asarray(r["xd"])
    np.testing.assert_allclose(E - E[0], W, atol=1e-9 * E[0])
    assert W[-1] < -2e-4  # it does damp: about half the initial strain energy (4e-4 J)
    # independent: -int eta_d^T k_e K eta_d dt with K from the beam alone, Simpson on the samples
    _, K = jflex.beam_modal_matrices(jflex.make_beam(L, MU, EI, 2))
    p = k_e * np.einsum("ti,ij,tj->t", xd[:, 1:], np.asarray(K), xd[:, 1:])
    from scipy.integrate import simpson
    np.testing.assert_allclose(W[-1], -simpson(p, x=np.asarray(ts)), rtol=2e-4)


@pytest.mark.heavy  # ~100 s of compile on 2 cores; the fixed-length energy test above covers the mechanism
def test_sliding_link_on_flexible_hub_conserves_energy():
    """Seed 001 structure: revolute hub (flexible), prismatic link sliding through it (flexible,
    time-varying shapes). Without damping or input the total energy must stay constant: this checks
    the material-flow terms of the kinetic energy, which a wrong velocity would violate."""
    # the robot carries the rigid hub and link (include_rigid=False): hub rod on [0, 0.7] m, link
    # rod on [0.365, 1.065] m of the prismatic body frame (its free length at q = 0 is 0.365 m)
    def rod(mu, a, b):
        m, Izz = mu * (b - a), mu * (b**3 - a**3) / 3
        return [m, m * (a + b) / 2, 0, 0, 1e-6, 0, Izz, 0, 0, Izz]

    robot = jflex.make_robot(
        joint_names=["rev", "pri"], link_names=["hub", "link"], parents=[-1, 0], joint_types=["revolute", "prismatic"],
        placement_R=np.stack([np.eye(3)] * 2), placement_p=np.zeros((2, 3)), axis=[[0, 0, 1.0], [1.0, 0, 0]],
        inertia=np.array([rod(2.1424, 0.0, 0.7), rod(0.785, 0.365, 1.065)]), gravity=(0, 0, 0),
    )
    link = jflex.make_beam(0.365, 0.785, 6.33, 2)
    hub = jflex.make_beam(0.7, 2.1424, 3000.0, 1)
    eff = FlexibleLink("hub", link, sliding_joint="pri", hub=hub, include_rigid=False, name="arm")
    model = jflex.Model(robot, [eff])
    ts = jnp.linspace(0, 1.0, 101)
    x0 = jnp.array([0.0, 0.0, 1e-4, 5e-3, -5e-4])
    xd0 = jnp.array([1.0, 0.1, 0.0, 0.0, 0.0])
    r = jflex.simulate(model, ts, x0, xd0, rtol=1e-11, atol=1e-13, outputs=("energy", "arm.length"),
                       solver=diffrax.Dopri8(), max_steps=200_000)
    E = np.asarray(r["energy"])
    assert np.max(np.abs(E - E[0])) / E[0] < 1e-8
    assert float(r["arm.length"][-1]) > 0.4  # it did slide (centrifugal pull outward)


def test_strain_output_is_minus_half_thickness_times_curvature():
    model = _spin_model(0.0)
    eff, slots = model.effects[0], model.layout.slots[0]
    x = jnp.array([0.3, 0.01, -0.002])
    z = jnp.zeros(model.nz)
    out = lambda name: float(eff.output(model.rigid, slots, name, x, x, z))
    s, h = 0.3, 1e-4
    curv = (out(f"beam.deflection@{s + h}") - 2 * out(f"beam.deflection@{s}") + out(f"beam.deflection@{s - h}")) / h**2
    np.testing.assert_allclose(out(f"beam.curvature@{s}"), curv, rtol=1e-5)
    np.testing.assert_allclose(out(f"beam.strain@{s}"), -0.001 * curv, rtol=1e-5)
    np.testing.assert_allclose(out("beam.tip_deflection"), 0.01 - 0.002, rtol=1e-12)


def _seed001_rigid_hub(extension=0.0, modes=2):
    """Seed-001 structure with a rigid hub: revolute hub rod [0, 0.7] m, link (0.7 m, 0.785 kg/m,
    EI 6.33 N m^2) sliding through it with free length 0.365 m + the prismatic coordinate."""
    def rod(mu, a, b):
        m, Izz = mu * (b - a), mu * (b**3 - a**3) / 3
        return [m, m * (a + b) / 2, 0, 0, 1e-6, 0, Izz, 0, 0, Izz]

    robot = jflex.make_robot(
        joint_names=["rev", "pri"], link_names=["hub", "link"], parents=[-1, 0], joint_types=["revolute", "prismatic"],
        placement_R=np.stack([np.eye(3)] * 2), placement_p=np.zeros((2, 3)), axis=[[0, 0, 1.0], [1.0, 0, 0]],
        inertia=np.array([rod(2.1424, 0.0, 0.7), rod(0.785, 0.365, 1.065)]), gravity=(0, 0, 0),
    )
    eff = FlexibleLink("hub", jflex.make_beam(0.365, 0.785, 6.33, modes), root=(0.7, 0.0, 0.0), sliding_joint="pri",
                       include_rigid=False, name="arm")
    return jflex.Model(robot, [eff])


def test_sliding_link_frequencies_follow_the_free_length_and_power_balance():
    """The time-varying shapes must give, with the joints held, the clamped-free frequencies of the
    current free length (0.365 m + extension), and the undamped sliding link's equations must
    conserve T + V at any state: dE/dt = xd . dE/dx + xdd . dE/dxd = 0 (pointwise, no solve)."""
    model = _seed001_rigid_hub()
    lin = eqx.filter_jit(jflex.linearize)
    for ext in (0.0, 0.1, -0.1):
        x0 = jnp.array([0.3, ext, 0.0, 0.0])
        w = _eig(lin(model, x0, hold=("rev", "pri")))
        ref = jflex.clamped_free_frequencies(jflex.make_beam(0.365 + ext, 0.785, 6.33, 2))
        np.testing.assert_allclose(w, np.asarray(ref), rtol=1e-6)

    @eqx.filter_jit
    def energy_rate(model, x, xd):
        xdd, _ = jflex.model_forward_dynamics(model, 0.0, x, xd, jnp.zeros(model.nz), jnp.zeros(2))
        E, dE = jax.jvp(lambda a, b: jflex.total_energy(model, a, b), (x, xd), (xd, xdd))
        return E, dE, xdd

    E, dE, xdd = energy_rate(model, jnp.array([0.3, 0.05, 2e-3, -3e-4]), jnp.array([1.2, 0.06, -0.05, 0.2]))
    assert abs(float(dE)) < 1e-12 * float(E)  # E ~ 0.4 J, rates ~ 1-10 /s
    # the sliding link is pulled outward: xdd of the prismatic coordinate has the centrifugal sign
    assert float(xdd[1]) > 0


def _load_seed001_experiment():
    import importlib.util
    import pathlib
    path = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "seed001_rp_arm.py"
    spec = importlib.util.spec_from_file_location("seed001_rp_arm", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.heavy  # ~40 s (compile of the sliding-link solve) on 2 cores
def test_seed001_loading_keeps_the_link_within_its_stroke():
    """Seed 001 with its loading (constant torque, +/- 65 mm/s ball-screw drive, brake at 1.8 s) at
    low resolution (rigid hub, one link mode): the link must go out about 0.9 s x 65 mm/s and
    come back, never beyond its 0.7 m length or into the hub, the drive must respect its 65 mm/s
    limit and the brake must stop the arm. (Without the drive's speed limit and no-back-drive
    reaction, the centrifugal pull ran the link out to ~1.1 m.)"""
    E = _load_seed001_experiment()
    cfg = jflex.load_yaml(__import__("pathlib").Path(E.__file__).parents[1] / "configs" / "seed001_rp_arm_quick.yaml")
    cfg["link"]["modes"], cfg["t_end_s"], cfg["rtol"], cfg["atol"] = 1, 2.4, 1e-5, 1e-7
    ts = np.linspace(0.0, 2.4, 241)
    _, _, o, _, _ = E.simulate_variant(cfg, "F.L-R.H", ts, ("arm.length", "pri_d", "rev", "rev_d"))
    l = o["arm.length"]
    ld = cfg["loading"]
    assert 0.3 < l.min() and l.max() < 0.7
    np.testing.assert_allclose(l.max(), 0.365 + 0.065 * ld["prismatic_switch_s"], atol=5e-3)  # out ~58 mm at 65 mm/s
    back = 0.365 + 0.065 * (2 * ld["prismatic_switch_s"] - ld["prismatic_stop_s"])  # and back in
    assert abs(l[-1] - back) < 8e-3
    assert np.max(np.abs(o["pri_d"])) < 0.0655
    assert abs(o["rev_d"][-1]) < 0.02 and o["rev"][-1] > 0.5  # turned ~1.3 rad, then braked to rest
