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
from _references import fe_beam_matrices

MU, L, EI = 0.157, 0.8, 0.349


def _eig(lin):
    w2 = sl.eigh(np.asarray(lin.K), np.asarray(lin.M), eigvals_only=True)
    return np.sqrt(np.clip(w2, 0, None))


def _seed001_robot():
    """The rigid carrier of the seed-001 arm (include_rigid=False): hub rod on [0, 0.7] m, link rod
    on [0.365, 1.065] m of the prismatic body frame, no gravity."""
    def rod(mu, a, b):
        m, Izz = mu * (b - a), mu * (b**3 - a**3) / 3
        return [m, m * (a + b) / 2, 0, 0, 1e-6, 0, Izz, 0, 0, Izz]

    return jflex.make_robot(
        joint_names=["rev", "pri"], link_names=["hub", "link"], parents=[-1, 0], joint_types=["revolute", "prismatic"],
        placement_R=np.stack([np.eye(3)] * 2), placement_p=np.zeros((2, 3)), axis=[[0, 0, 1.0], [1.0, 0, 0]],
        inertia=np.array([rod(2.1424, 0.0, 0.7), rod(0.785, 0.365, 1.065)]), gravity=(0, 0, 0),
    )


def _fe_hub(L, m, EI, Ih, ne=60, k=3):
    """FE beam whose root rotation is free and carries the hub inertia ``Ih`` (pinned hub)."""
    K, M = fe_beam_matrices(L, m, EI, ne)
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
    robot = _seed001_robot()
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


def _seed001_rigid_hub(extension=0.0, modes=2, foreshortening=False):
    """Seed-001 structure with a rigid hub: revolute hub rod [0, 0.7] m, link (0.7 m, 0.785 kg/m,
    EI 6.33 N m^2) sliding through it with free length 0.365 m + the prismatic coordinate."""
    robot = _seed001_robot()
    eff = FlexibleLink("hub", jflex.make_beam(0.365, 0.785, 6.33, modes), root=(0.7, 0.0, 0.0), sliding_joint="pri",
                       include_rigid=False, name="arm", foreshortening=foreshortening)
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


# ---- foreshortening: centrifugal stiffening and energy ----------------------------------------

def _southwell(n, hub_ratio=0.0):
    """Independent reference: Southwell coefficient K_n = int_0^1 N(x) phi_n'^2 dx / int_0^1 phi_n^2 dx
    of a uniform clamped-free Euler-Bernoulli beam on a hub of radius ``hub_ratio`` * L, with the
    centrifugal axial force N(x) / (rho A Omega^2 L^2) = r (1 - x) + (1 - x^2) / 2 (first-order
    perturbation of omega^2 in Omega^2 with the exact non-rotating mode). Closed-form modes,
    scipy roots and adaptive quadrature: none of jflex's beam code."""
    from scipy.integrate import quad
    from scipy.optimize import brentq
    b = brentq(lambda b: 1 + np.cos(b) * np.cosh(b), (n - 0.5) * np.pi - 0.6, (n - 0.5) * np.pi + 0.6, xtol=1e-15)
    sg = (np.cosh(b) + np.cos(b)) / (np.sinh(b) + np.sin(b))
    phi = lambda x: np.cosh(b * x) - np.cos(b * x) - sg * (np.sinh(b * x) - np.sin(b * x))
    dphi = lambda x: b * (np.sinh(b * x) + np.sin(b * x) - sg * (np.cosh(b * x) - np.cos(b * x)))
    N = lambda x: hub_ratio * (1 - x) + 0.5 * (1 - x * x)
    num = quad(lambda x: N(x) * dphi(x) ** 2, 0, 1, epsabs=0, epsrel=1e-13, limit=200)[0]
    return num / quad(lambda x: phi(x) ** 2, 0, 1, epsabs=0, epsrel=1e-13, limit=200)[0]


@eqx.filter_jit
def _spin_system(model, q0, qd0):
    """First-order system matrix (2m, 2m) of the flexible coordinates about steady motion: the
    rigid joints follow q0 + qd0 t exactly (prescribed, qdd = 0; the hub spin is then a relative
    equilibrium, not a rest one, so jflex.linearize does not apply), the beam straight. Also
    returns the flexible bias forces at that state (0 for a relative equilibrium, which is what
    lets the Jacobian of M^-1 h be M^-1 times that of h)."""
    n, m = q0.shape[0], model.nx - q0.shape[0]
    z = jnp.zeros(model.nz)

    def h(y):
        x, xd = jnp.concatenate([q0, y[:m]]), jnp.concatenate([qd0, y[m:]])
        return jflex.bias_forces(model, 0.0, x, xd, z)[n:]

    y0 = jnp.zeros(2 * m)
    M = jflex.mass_matrix(model, jnp.concatenate([q0, y0[:m]]))[n:, n:]
    # the Jacobian of h by central differences of one vmapped h: it compiles in under half the
    # time of jax.jacfwd(h) (56 s against 24 s on a loaded 2-core machine), and the difference
    # error (~1e-10 relative at this step: h is smooth and nearly quadratic about the straight
    # beam) is far below what the slopes are checked to
    step = 1e-6
    E = step * jnp.eye(2 * m)
    hp = jax.vmap(h)(jnp.concatenate([y0 + E, y0 - E, y0[None]]))
    J = -jnp.linalg.solve(M, ((hp[:2 * m] - hp[2 * m:-1]) / (2 * step)).T)
    return jnp.block([[jnp.zeros((m, m)), jnp.eye(m)], [J]]), hp[-1]


def _stiffening_slopes(model, q0, spin_axis_dof, w_ref, k=2):
    """Slopes d(omega_i^2)/d(Omega^2), i < k, fitted over Omega = 0 ... 0.3 w_ref."""
    oms = w_ref * np.array([0.0, 0.1, 0.2, 0.3])
    w2 = []
    for om in oms:
        qd0 = jnp.zeros(q0.shape[0]).at[spin_axis_dof].set(om)
        A, a0 = _spin_system(model, q0, qd0)
        assert np.max(np.abs(np.asarray(a0))) < 1e-9  # steady spin with a straight beam is a relative equilibrium
        ev = np.linalg.eigvals(np.asarray(A))
        assert np.max(np.abs(ev.real)) < 1e-6 * w_ref  # undamped, no flutter at these rates
        w2.append(np.sort(np.abs(ev.imag))[::2][:k] ** 2)  # the eigenvalues come in +- i omega pairs
    return np.polyfit(oms**2, np.array(w2), 1)[0]


def test_foreshortening_gives_southwell_centrifugal_stiffening():
    """A uniform clamped-free Euler-Bernoulli beam on a hub of zero radius, spinning at a constant
    rate Omega about z, bending in the plane of rotation (FlexibleLink bends in the body x-y plane
    of a hub turning about z: the in-plane / chordwise case). Southwell:
    omega_n^2 = omega_n0^2 + (K_n - 1) Omega^2, K_n Omega^2 the centrifugal (foreshortening)
    stiffening, -Omega^2 the in-plane softening of the rotating frame (flapwise would be + K_n).

    Reference: the first Southwell coefficient of the uniform cantilever with zero hub radius,
    K_1 = 1.193, as tabulated in the rotor-blade literature (e.g. Bisplinghoff, Ashley & Halfman,
    Aeroelasticity, 1955; the `search` tool found no page carrying the table, so the value is
    quoted from memory and recomputed here): :func:`_southwell` gives K_1 = 1.19334 and
    K_2 = 6.4793 from the closed-form modes, independently of jflex's beam code.

    Measured: slopes of omega^2 against Omega^2 (least squares over Omega = 0, 0.1, 0.2,
    0.3 omega_1) of the equations of motion linearised about steady spin, 3 modes: K_1 - 1 =
    0.19203 (-0.67 %, the curvature of omega^2(Omega^2) over the fit range; the 1-mode model
    gives 0.193336 exactly, the exact first mode being in the basis), K_2 - 1 = 5.4793 (+0.02 %).
    Without foreshortening only the softening remains: slope -1 exactly, so a missing or wrong
    stiffening fails the test."""
    K1, K2 = _southwell(1), _southwell(2)
    assert abs(K1 - 1.1933) < 1e-4
    w1 = float(jflex.clamped_free_frequencies(jflex.make_beam(L, MU, EI, 1))[0])
    q0 = jnp.zeros(1)
    slopes = {}
    for fs in (True, False):
        model = jflex.Model(rotor(0.02), [FlexibleLink("hub", jflex.make_beam(L, MU, EI, 3), foreshortening=fs)])
        slopes[fs] = _stiffening_slopes(model, q0, 0, w1)
    np.testing.assert_allclose(slopes[True], [K1 - 1, K2 - 1], rtol=0.02)
    np.testing.assert_allclose(slopes[False], [-1.0, -1.0], rtol=1e-6)


def test_foreshortening_scales_with_a_sliding_links_free_length():
    """Same check for a sliding link (time-varying length l = 0.365 m + extension, shapes scaled
    with l) clamped at hub radius R = 0.7 m: with the hub spinning and the prismatic joint held,
    the slope is K_1(R / l) - 1 with the hub-radius term r (1 - x) in the axial force (3.206 at
    l = 0.365 m, 2.329 at 0.515 m; measured -0.16 %, 2 modes). A wrong length scaling of the
    shortening (nominal instead of current length, or a missing 1/l) would change it by the
    ratio of lengths. ~22 s of compile on 2 cores."""
    model = _seed001_rigid_hub(modes=2, foreshortening=True)
    for ext in (0.0, 0.15):
        l = 0.365 + ext
        w1 = float(jflex.clamped_free_frequencies(jflex.make_beam(l, 0.785, 6.33, 1))[0])
        s = _stiffening_slopes(model, jnp.array([0.0, ext]), 0, w1, k=1)
        np.testing.assert_allclose(s[0], _southwell(1, 0.7 / l) - 1, rtol=0.02)


def test_foreshortening_conserves_energy():
    """Undamped rotor + link with foreshortening, in-plane gravity, a large deflection (tip 5 cm
    on 0.8 m) and a fast spin: T + V constant along a simulation (~11 s on 2 cores)."""
    beam = jflex.make_beam(L, MU, EI, 2)
    model = jflex.Model(rotor(0.02, gravity=(0.0, -9.81, 0.0)), [FlexibleLink("hub", beam, foreshortening=True)])
    period = 2 * np.pi / float(jflex.clamped_free_frequencies(beam)[0])
    ts = jnp.linspace(0, 4 * period, 201)
    r = jflex.simulate(model, ts, jnp.array([0.0, 0.05, -0.004]), jnp.array([4.0, 0.0, 0.0]),
                       rtol=1e-12, atol=1e-14, outputs=("energy",))
    E = np.asarray(r["energy"])
    assert np.max(np.abs(E - E[0])) / np.max(np.abs(E)) < 1e-8


def test_foreshortening_power_balance_sliding_link_on_flexible_hub():
    """Pointwise dE/dt = xd . dE/dx + xdd . dE/dxd = 0 of the undamped sliding link on a flexible hub
    with foreshortening of both (time-varying length, material flow, hub-tip shortening at once;
    ~18 s of compile on 2 cores)."""
    base = _seed001_rigid_hub(modes=2)
    hub = jflex.make_beam(0.7, 2.1424, 3000.0, 1)
    eff = FlexibleLink("hub", jflex.make_beam(0.365, 0.785, 6.33, 2), sliding_joint="pri", hub=hub,
                       include_rigid=False, name="arm", foreshortening=True)
    model = jflex.Model(base.robot, [eff])

    @eqx.filter_jit
    def energy_rate(model, x, xd):
        xdd, _ = jflex.model_forward_dynamics(model, 0.0, x, xd, jnp.zeros(model.nz), jnp.zeros(2))
        return jax.jvp(lambda a, b: jflex.total_energy(model, a, b), (x, xd), (xd, xdd))

    E, dE = energy_rate(model, jnp.array([0.3, 0.05, 3e-3, 2e-2, -3e-3]), jnp.array([1.2, 0.06, 0.1, -0.05, 0.2]))
    assert abs(float(dE)) < 1e-12 * float(E)


def test_tip_frf_of_a_flexible_link_includes_its_deflection():
    # joint held: the beam is a cantilever; its tip receptance tends to the static compliance
    # L^3 / (3 EI) and peaks at the first clamped frequency 1.875^2 sqrt(EI / (mu L^4))
    model = jflex.Model(rotor(0.02), [FlexibleLink("hub", jflex.make_beam(L, MU, EI, 4), damping=KelvinVoigt(1e-3))])
    q0 = jnp.zeros(1)
    w1 = 1.8751**2 * np.sqrt(EI / (MU * L**4))
    omega = jnp.array([1e-3 * w1, 0.999 * w1, w1, 1.001 * w1])
    frf = eqx.filter_jit(jflex.frf)
    G = np.asarray(frf(model, q0, omega, hold=("j1",), frame="beam.tip_position"))
    np.testing.assert_allclose(G[0, 1, 1].real, L**3 / (3 * EI), rtol=2e-3)  # 4 modes: 0.9993 of it
    assert np.abs(G[0, 0, 0]) < 1e-6 * np.abs(G[0, 1, 1])  # no axial compliance (no foreshortening)
    peak = np.abs(G[1:, 1, 1])
    assert peak[1] > peak[0] and peak[1] > peak[2]
    # a rigid frame on the hub is not carried by the beam's modes
    assert np.all(np.asarray(frf(model, q0, omega, hold=("j1",), frame="hub")) == 0)
    with pytest.raises(jflex.ShapeError, match="effect output"):
        frf(model, q0, omega, hold=("j1",), frame="beam.tip_position", components="full")
