"""Free vibration of a rigid-flexible planar arm under viscous, fractional and hysteretic damping.

The arm of the paper "Numerical Implementation and Comparison Between the Viscous, Fractional and
Hysteretic Damping Models of a Rigid-Flexible Planar Manipulator": free vibration of a rigid-
flexible planar arm under viscous, fractional and hysteretic damping (Table V), tip decay and power
spectra (their Figs. 4 and 6 as qualitative reference), and the damping-from-modes relation Eq. 30.

Usage: python experiments/seed004_damping.py [configs/seed004_rigid_flexible_arm.yaml] [--out DIR]
"""

import pathlib
import sys
from typing import Annotated

import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import scipy.linalg as sl  # noqa: E402

import jflex  # noqa: E402
from jflex.effects import FlexibleLink, Fractional, Hysteretic, KelvinVoigt  # noqa: E402
from pydantic import BaseModel, ConfigDict, Field, model_validator  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent


class JointHold(jflex.effects.AbstractEffect):
    """A PD servo on both joints (kept local: it stands in for the paper's controller). The P part
    is a potential, so the energy balance counts only what the dampers dissipate."""

    kp: jnp.ndarray
    kd: jnp.ndarray

    def potential_energy(self, robot, slots, x):
        return 0.5 * self.kp * jnp.sum(x[:2] ** 2)

    def generalized_force(self, robot, slots, t, x, xd, z):
        return jnp.zeros(slots.nx).at[:2].set(-self.kd * xd[:2])


def build(cfg, law):
    a = cfg["arm"]
    Lr = float(a["rigid_link_length_m"])
    I1 = float(a["I_R0_plus_mH_Lr2_kg_m2"])
    IH = float(a["I_H_kg_m2"])
    # link 1 carries I_R0 + m_H L_r^2 about joint 1 (the hub mass at L_r only adds to that sum in a
    # planar arm); link 2 is the hub of joint 2 with I_H; the beam is the effect's.
    robot = jflex.make_robot(
        joint_names=["joint1", "joint2"], link_names=["link1", "hub2"], parents=[-1, 0],
        joint_types=["revolute", "revolute"], placement_R=np.stack([np.eye(3)] * 2),
        placement_p=np.array([[0, 0, 0], [Lr, 0, 0.0]]), axis=[[0, 0, 1.0]] * 2,
        inertia=np.array([[1e-3, 0, 0, 0, 1e-6, 0, I1, 0, 0, I1], [1e-3, 0, 0, 0, 1e-6, 0, IH, 0, 0, IH]]),
        gravity=(0, 0, -9.81),  # the arm moves in a horizontal plane
    )
    beam = jflex.make_beam(float(a["flexible_link_length_m"]), float(a["rho_A_kg_per_m"]), float(a["EI3_N_m2"]),
                           int(a["modes"]), rotary_inertia=float(a["rho_I3_kg_m"]))
    hold = JointHold(jnp.asarray(float(cfg["joint_hold"]["kp_N_m_per_rad"])), jnp.asarray(float(cfg["joint_hold"]["kd_N_m_s_per_rad"])))
    return jflex.Model(robot, [hold, FlexibleLink("hub2", beam, damping=law, name="beam")]), beam


def laws(cfg):
    d = cfg["damping"]
    f = d["fractional"]
    h = d["hysteretic"]
    return {
        "undamped": None,
        "viscous": KelvinVoigt(float(d["viscous"]["k_e_s"])),
        "fractional": Fractional(float(f["k_e"]), float(f["alpha"]), tuple(f["band_rad_per_s"]), int(f["order"])),
        # F = k_e f(x) with f the Masing element of (h0, delta): the same as an element of k_e h0
        "hysteretic": Hysteretic(float(h["k_e"]), float(h["k_e"]) * float(h["h0_N"]), float(h["delta_m"]),
                                 float(h["reversal_rate_per_s"])),
    }


def eq30_zeta(k_e, alpha, w):
    """Eq. 30 of the damping paper solved for zeta: zeta = k_e w^a sin(pi a / 2) / (1 + k_e w^a cos(pi a / 2))."""
    g = k_e * w**alpha
    return g * np.sin(np.pi * alpha / 2) / (1 + g * np.cos(np.pi * alpha / 2))


def run(cfg, out):
    ts = np.linspace(0, float(cfg["t_end_s"]), int(cfg["samples"]))
    tol = dict(rtol=float(cfg["rtol"]), atol=float(cfg["atol"]))
    res = {"filled_values": {"rigid_link_length_m": cfg["arm"]["rigid_link_length_m"],
                             "flexible_link_length_m": cfg["arm"]["flexible_link_length_m"],
                             "joint_hold": cfg["joint_hold"], "initial_tip_deflection_m": cfg["initial_tip_deflection_m"]}}
    model0, beam = build(cfg, None)
    x0 = jnp.zeros(model0.nx)
    lin = jflex.linearize(model0, x0, hold=("joint1", "joint2"))
    w_clamped = np.sqrt(sl.eigh(np.asarray(lin.K), np.asarray(lin.M), eigvals_only=True))
    res["clamped_link_frequencies_Hz"] = w_clamped / (2 * np.pi)
    lin_all = jflex.linearize(model0, x0)
    w_all = np.sqrt(np.clip(sl.eigh(np.asarray(lin_all.K), np.asarray(lin_all.M), eigvals_only=True), 0, None))
    res["held_arm_frequencies_Hz"] = w_all / (2 * np.pi)

    # initial state: first clamped mode shape scaled to the requested tip deflection, at rest
    _, vecs = sl.eigh(np.asarray(lin.K), np.asarray(lin.M))
    v1 = vecs[:, 0] / np.sum(vecs[:, 0])  # unit tip deflection (shapes have phi(1) = 1)
    d0 = float(cfg["initial_tip_deflection_m"])
    x0 = jnp.concatenate([jnp.zeros(2), jnp.asarray(d0 * v1)])

    fig, ax = plt.subplots(2, 1, figsize=(10, 8))
    decay = {}
    for name, law in laws(cfg).items():
        model, _ = build(cfg, law)
        z0 = None
        if isinstance(law, Hysteretic):  # loaded along the virgin curve to the initial deflection
            z0 = law.loaded_state(jnp.array([d0]))
        r = jflex.simulate(model, ts, x0=x0, z0=z0, outputs=("beam.tip_deflection", "energy", "work", "joint2"),
                           max_steps=400_000, **tol)
        y = np.asarray(r["beam.tip_deflection"])
        E, W = np.asarray(r["energy"]), np.asarray(r["work"])
        peaks = [np.max(np.abs(y[(ts >= t) & (ts < t + 1.0)])) for t in range(int(ts[-1]))]
        f, P = _spectrum(ts, y)
        decay[name] = {
            "tip_peak_per_second_m": peaks,
            "initial_energy_J": float(E[0]),
            "energy_balance_error_J": float(np.max(np.abs(E - E[0] - W))),
            "energy_lost_fraction": float(-W[-1] / E[0]),
            "spectrum_peak_Hz": float(f[np.argmax(P[f > 0.2]) + np.sum(f <= 0.2)]),
        }
        ax[0].plot(ts, 1e3 * y, label=name, lw=0.8)
        ax[1].semilogy(f, P, label=name, lw=0.8)
    res["free_vibration"] = decay
    ax[0].set(xlabel="t [s]", ylabel="tip deflection [mm]", title="free vibration of the tip (cf. Fig. 6 of the damping paper)")
    ax[1].set(xlabel="f [Hz]", ylabel="power spectrum [m^2/Hz]", xlim=(0, 40), title="spectrum (cf. Fig. 4)")
    for a in ax:
        a.legend()
    fig.tight_layout()
    fig.savefig(out / "seed004_tip_and_spectrum.png", dpi=120)

    # Eq. 30 with the "modes parameters" of Table V at the first two clamped frequencies
    mp = cfg["modes_parameters"]
    w12 = w_clamped[:2]
    frac = mp["fractional"]
    z_frac = eq30_zeta(frac["k_e"], frac["alpha"], w12)
    z_visc = mp["viscous"]["k_e_s"] * w12  # Eq. 31
    # what the model's complex stiffness k (1 + k_e (i w)^a) gives: loss factor eta, damping ratio eta / 2
    g = frac["k_e"] * (1j * w12) ** frac["alpha"]
    eta = np.imag(g) / (1 + np.real(g))
    res["eq30"] = {
        "omega_rad_per_s": w12,
        "zeta_fractional_eq30": z_frac,
        "zeta_viscous_eq31": z_visc,
        "loss_factor_from_complex_stiffness_fractional": eta,
        "damping_ratio_fractional_eta_over_2": eta / 2,
        "note": "Eq. 30 as printed equals the loss factor eta of k(1 + k_e (i w)^alpha); the modal damping "
                "ratio is eta / 2 (for alpha = 1, zeta = k_e w / 2, not k_e w as in Eq. 31)",
    }
    return res


def _spectrum(ts, y):
    dt = ts[1] - ts[0]
    Y = np.fft.rfft((y - y.mean()) * np.hanning(y.size))
    return np.fft.rfftfreq(y.size, dt), (np.abs(Y) ** 2) * dt / y.size


# --- the config's schema (jflex.experiment_cli validates the YAML against it) ------------------------
class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


Positive = Annotated[float, Field(gt=0)]


class ArmConfig(_Strict):
    rigid_link_length_m: Positive
    I_R0_plus_mH_Lr2_kg_m2: Positive = Field(description="link 1 + hub inertia about joint 1 [kg m^2]")
    I_H_kg_m2: Positive = Field(description="hub inertia about joint 2 [kg m^2]")
    flexible_link_length_m: Positive
    rho_A_kg_per_m: Positive
    rho_I3_kg_m: Annotated[float, Field(ge=0)] = Field(description="rotary inertia per length (0: Euler-Bernoulli)")
    EI3_N_m2: Positive
    modes: Annotated[int, Field(ge=1)]


class JointHoldConfig(_Strict):
    kp_N_m_per_rad: Positive
    kd_N_m_s_per_rad: Annotated[float, Field(ge=0)]


class ViscousConfig(_Strict):
    k_e_s: Annotated[float, Field(ge=0)] = Field(description="Kelvin-Voigt coefficient [s]")


class FractionalConfig(_Strict):
    k_e: Annotated[float, Field(ge=0)]
    alpha: Annotated[float, Field(gt=0, le=1)] = Field(description="fractional order, in (0, 1]")


class FractionalLawConfig(FractionalConfig):
    band_rad_per_s: Annotated[list[Positive], Field(min_length=2, max_length=2)] = Field(
        description="band of the rational approximation [rad/s]")
    order: Annotated[int, Field(ge=1)]

    @model_validator(mode="after")
    def _band(self):
        if self.band_rad_per_s[1] <= self.band_rad_per_s[0]:
            raise ValueError(f"band_rad_per_s must rise, got {self.band_rad_per_s}")
        return self


class HystereticConfig(_Strict):
    k_e: Annotated[float, Field(ge=0)]
    h0_N: Positive
    delta_m: Positive
    reversal_rate_per_s: Positive


class DampingConfig(_Strict):
    viscous: ViscousConfig
    fractional: FractionalLawConfig
    hysteretic: HystereticConfig


class ModesParametersConfig(_Strict):
    viscous: ViscousConfig
    fractional: FractionalConfig


class Seed004DampingConfig(_Strict):
    arm: ArmConfig
    joint_hold: JointHoldConfig
    damping: DampingConfig
    modes_parameters: ModesParametersConfig
    initial_tip_deflection_m: float
    t_end_s: Positive
    samples: Annotated[int, Field(ge=2)]
    rtol: Positive
    atol: Positive


def quick_figures(res) -> dict:
    """The key figures of ``--quick``, loosely: the clamped link's first two frequencies against
    the Euler-Bernoulli cantilever's (1.875^2 and 4.694^2 sqrt(EI / rho A L^4) / 2 pi, 1.703 and
    10.67 Hz for Table I's strip of 0.7 m; the assumed modes and the strip's rotary inertia differ
    by well under 1 %), the energy balance of every free vibration, and that only the dampers lose
    energy."""
    fv = res["free_vibration"]
    f = res["clamped_link_frequencies_Hz"]
    out = {"clamped link, mode 1 [Hz]": (f[0], 1.703 * 0.98, 1.703 * 1.02),
           "clamped link, mode 2 [Hz]": (f[1], 10.67 * 0.97, 10.67 * 1.03),
           "undamped, energy lost fraction": (fv["undamped"]["energy_lost_fraction"], -1e-4, 1e-4)}
    for name, d in fv.items():
        out[f"{name}, energy balance error / initial energy"] = (d["energy_balance_error_J"] / d["initial_energy_J"], 0.0, 1e-3)
        if name != "undamped":
            out[f"{name}, energy lost fraction"] = (d["energy_lost_fraction"], 0.01, 1.0)
    return out


def main(argv=None):
    return jflex.experiment_cli("seed004_damping", HERE.parent / "configs" / "seed004_rigid_flexible_arm.yaml", run, argv,
                                schema=Seed004DampingConfig,
                                quick=(HERE.parent / "configs" / "seed004_rigid_flexible_arm_quick.yaml", quick_figures))


if __name__ == "__main__":
    main(sys.argv[1:])
