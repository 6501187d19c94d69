"""Synthetic recovery: noisy data from known models, parameters recovered with jflex.identify.

1. Rigid + friction (equation error): a Fourier excitation optimised for cond(A), noisy joint
   positions filtered and differentiated spectrally, noisy torques; OLS and WLS of the base
   parameters (friction and gravity-compensator terms included) against the planted values,
   then a physically consistent full set (log-Cholesky) lifted from them.
2. Flexible joints (output error): multi-posture tool FRFs with 2 % noise, K and C fitted from a
   +/-50 % start.
3. A flexible link: tip free vibration with Kelvin-Voigt damping, EI and k_e fitted from +/-50 %.

Each case reports the error of every parameter in units of its reported standard deviation.

    python experiments/identify_synthetic.py [CONFIG] [--out DIR]
"""

from __future__ import annotations

import pathlib

import jax
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import jflex
from jflex import identify as idf

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT = ROOT / "configs" / "identify_synthetic.yaml"
DH = [[0, 0, 0.642, 0], [np.pi / 2, 0.25, 0, 0], [0, 0.95, 0, 0]]


def arm():
    inert = [{"mass": 60.0, "com": [0.0, -0.05, -0.2], "inertia": [4.0, 0.1, 3.5, 0.0, 0.2, 3.0]},
             {"mass": 45.0, "com": [0.45, 0.02, 0.1], "inertia": [0.6, 0.05, 4.0, 0.1, 0.0, 4.2]},
             {"mass": 30.0, "com": [0.5, 0.01, 0.0], "inertia": [0.3, 0.0, 2.6, 0.05, 0.0, 2.7]}]
    return jflex.from_dh(DH, tool=[0, 0.994, 0, 0], inertias=inert,
                         lower=[-2.5, -0.5, -2.2], upper=[0.5, 2.6, 0.1], velocity_limit=[2.6, 2.6, 2.6])


def rigid_friction(c, rng, run_dir):
    robot = arm()
    fv, fc, B = (np.asarray(c[k], float) for k in ("viscous_N_m_s_per_rad", "coulomb_N_m", "compensator_N_m"))
    reg = idf.Regressor(compensator=(1, 3))
    bp = idf.base_parameters(robot, reg)
    ex = c["excitation"]
    design = idf.design_excitation(robot, idf.base_parameters(robot), n_harmonics=int(ex["n_harmonics"]),
                                   omega_f=float(ex["omega_f_rad_per_s"]), n_samples=int(ex["n_design_samples"]),
                                   max_steps=int(ex["max_steps"]), penalties=(1e2, 1e4))
    traj = design.trajectory
    T = float(traj.period)
    fs = float(c["sample_rate_Hz"])
    n_per = T * fs
    if abs(n_per - round(n_per)) > 1e-6:
        raise jflex.ConfigError(f"rigid_friction: one period holds {n_per:.4f} samples; spectral differentiation needs whole periods "
                                "(choose omega_f and sample_rate_Hz so that 2 pi fs / omega_f is an integer)")
    t = np.arange(int(round(c["periods"] * n_per))) / fs
    q, qd, qdd = (np.asarray(a) for a in traj.sample(t))
    theta = np.asarray(reg.vector(robot, fv=fv, fc=fc, compensator=B))
    tau = np.asarray(reg.stack(robot, q, qd, qdd) @ theta).reshape(-1, 3)
    sig = np.asarray(c["torque_noise_N_m"], float)
    q_m = q + rng.normal(size=q.shape) * float(c["position_noise_rad"])
    tau_m = tau + rng.normal(size=tau.shape) * sig
    qf, qdf, qddf = idf.spectral_derivatives(q_m, 1 / fs, cutoff=float(c["cutoff_Hz"]))
    # Torques are not low-passed: their Coulomb steps would be smoothed while the regressor's
    # sign(qd) columns are not (a bias); white torque noise is what least squares averages out.
    taf = tau_m
    A = np.asarray(bp.columns(reg.stack(robot, qf, qdf, qddf)))
    truth = np.asarray(bp.project(theta))
    out = {"base_parameter_count": bp.rank, "groups": bp.report(), "excitation_cond": design.cond,
           "excitation_max_violation": design.max_violation}
    for name, res in (("ols", idf.ols(A, taf.ravel())), ("wls", idf.wls(A, taf.ravel(), 3))):
        z = (res.theta - truth) / res.std
        out[name] = {"max_abs_error_in_std": float(np.abs(z).max()), "fraction_within_2_std": float(np.mean(np.abs(z) < 2)),
                     "max_relative_error_pct": float(np.max(np.abs(res.theta - truth) / np.maximum(np.abs(truth), 1e-9)) * 100),
                     "cond": res.cond}
        print(f"rigid+friction {name}: max |error| = {out[name]['max_abs_error_in_std']:.2f} std, "
              f"{100 * out[name]['fraction_within_2_std']:.0f} % within 2 std")
    # Physically consistent full set from the WLS base parameters, with a CAD prior off by 30 %.
    psi = idf.wls(A, taf.ravel(), 3).theta
    prior = theta * rng.uniform(0.7, 1.3, size=theta.shape)
    prior[:30] = np.asarray(jflex.from_dh(DH, inertias=[{"mass": m, "com": [0.2, 0.0, 0.0], "inertia": [1, 0, 1, 0, 0, 1]} for m in (50.0, 40.0, 35.0)]).inertia).ravel()
    lift = idf.physical_fit(bp.matrix(), psi, 3, prior=prior, prior_weight=1e-4)
    out["physical_lift"] = {"consistent": [bool(idf.is_consistent(p)) for p in lift.inertia],
                            "max_base_mismatch_relative": float(np.abs(np.asarray(bp.project(lift.theta)) - psi).max() / np.abs(psi).max())}
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(t, q)
    ax[0].set_ylabel("q [rad]")
    ax[1].plot(t, tau_m, lw=0.6)
    ax[1].plot(t, (A @ psi).reshape(-1, 3), "k--", lw=0.8)
    ax[1].set(xlabel="t [s]", ylabel="torque [N m]", title="measured (noisy) and WLS-predicted torques")
    fig.tight_layout()
    fig.savefig(run_dir / "synthetic_rigid_friction.png", dpi=120)
    plt.close(fig)
    return out


def flexible_joints(c, rng, max_steps):
    robot = arm()
    K, C = np.asarray(c["stiffness_N_m_per_rad"], float), np.asarray(c["damping_N_m_s_per_rad"], float)
    mk = lambda K, C: jflex.Model(robot, [jflex.effects.FlexibleJoints(K, C, rotor_inertia=[1e-3] * 3, gear_ratio=[100.0] * 3, coupling=False)])
    post = np.asarray(c["postures_rad"], float)
    lo, hi, nf = c["f_Hz"]
    omega = 2 * np.pi * np.linspace(lo, hi, int(nf))
    H = np.asarray(jax.jit(jax.vmap(lambda q: jflex.frf(mk(K, C), q, omega, hold="actuated", frame="tool")))(jnp.asarray(post)))
    nz = float(c["noise_fraction"])
    Hn = H * (1 + nz * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape)))
    data = idf.FRFData(post, omega, Hn, frame="tool")
    spec = idf.ParameterSpec([idf.Free("K", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                              idf.Free("C", lambda m: m.effects[0].damping, transform=idf.Log())])
    res = idf.fit(mk(K * [1.5, 0.5, 1.5], C * [0.5, 1.5, 0.5]), spec, data, max_steps=max_steps, progress=10)
    zK = (res.values["K"] - K) / res.std["K"]
    zC = (res.values["C"] - C) / res.std["C"]
    print(f"flexible joints: K error {np.round(zK, 2)} std, C error {np.round(zC, 2)} std")
    return {"fit": res.to_dict(), "K_error_in_std": zK, "C_error_in_std": zC,
            "K_relative_error_pct": 100 * (res.values["K"] - K) / K, "C_relative_error_pct": 100 * (res.values["C"] - C) / C}


class ServoHold(jflex.effects.AbstractEffect):
    """A stiff spring holding the hub joint, so the beam vibrates as a cantilever."""

    kp: jnp.ndarray

    def potential_energy(self, robot, slots, x):
        return 0.5 * self.kp * x[0] ** 2


def flexible_link(c, rng, max_steps, run_dir):
    robot = jflex.make_robot(joint_names=["hub"], link_names=["hub"], parents=[-1], joint_types=["revolute"],
                             placement_R=np.eye(3)[None], placement_p=np.zeros((1, 3)), axis=[[0, 0, 1.0]],
                             inertia=np.array([[1e-3, 0, 0, 0, 1e-6, 0, 1e-3, 0, 0, 1e-3]]), gravity=(0, 0, -9.81))

    def mk(EI, ke):
        beam = jflex.make_beam(float(c["length_m"]), float(c["rho_A_kg_per_m"]), EI, int(c["modes"]))
        return jflex.Model(robot, [ServoHold(jnp.asarray(500.0)), jflex.effects.FlexibleLink("hub", beam, damping=jflex.effects.KelvinVoigt(ke), name="beam")])

    EI, ke = float(c["EI_N_m2"]), float(c["k_e_s"])
    true = mk(EI, ke)
    ts = np.linspace(0, float(c["t_end_s"]), int(c["samples"]), endpoint=False)
    x0 = np.zeros(true.nx)
    x0[1] = float(c["initial_tip_m"])  # first assumed mode, phi(1) = 1
    kw = dict(rtol=1e-8, atol=1e-10)
    y = np.asarray(jflex.simulate(true, ts, x0=jnp.asarray(x0), outputs=("beam.tip_deflection",), **kw)["beam.tip_deflection"])
    ym = y + rng.normal(size=y.shape) * float(c["noise_fraction_of_peak"]) * np.abs(y).max()
    data = idf.TimeData(ts, {"beam.tip_deflection": ym}, x0=x0, simulate_kw=kw, name="tip")
    spec = idf.ParameterSpec([idf.Free("EI", lambda m: m.effects[1].beam.EI, transform=idf.Log()),
                              idf.Free("k_e", lambda m: m.effects[1].damping.k_e, transform=idf.Log())])
    res = idf.fit(mk(EI * 1.5, ke * 0.5), spec, data, max_steps=max_steps, progress=5)
    z = {"EI": float((res.values["EI"] - EI) / res.std["EI"]), "k_e": float((res.values["k_e"] - ke) / res.std["k_e"])}
    print(f"flexible link: EI = {float(res.values['EI']):.4f} (true {EI}), k_e = {float(res.values['k_e']):.3e} (true {ke}); errors {z} std")
    fig, a = plt.subplots(figsize=(9, 4))
    a.plot(ts, 1e3 * ym, "k.", ms=2, label="noisy record")
    a.plot(ts, 1e3 * np.asarray(data.predict(res.model)["beam.tip_deflection"]), label="fit")
    a.set(xlabel="t [s]", ylabel="tip deflection [mm]")
    a.legend()
    fig.tight_layout()
    fig.savefig(run_dir / "synthetic_flexible_link.png", dpi=120)
    plt.close(fig)
    return {"fit": res.to_dict(), "error_in_std": z}


def run(cfg: dict, run_dir: pathlib.Path) -> dict:
    rng = np.random.default_rng(int(cfg.get("seed", 0)))
    ms = int(cfg.get("max_steps", 60))
    return {
        "rigid_friction": rigid_friction(cfg["rigid_friction"], rng, run_dir),
        "flexible_joints": flexible_joints(cfg["flexible_joints"], rng, ms),
        "flexible_link": flexible_link(cfg["flexible_link"], rng, ms, run_dir),
    }


def main(argv=None):
    return jflex.experiment_cli("identify_synthetic", DEFAULT, run, argv, description=__doc__)


if __name__ == "__main__":
    main()
