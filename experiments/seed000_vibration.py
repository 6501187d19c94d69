"""One-degree-of-freedom free, damped and forced responses and the Duhamel integral against closed forms.

The textbook cases of the course notes "Manipulator modeling accounting for flexibilities".

Usage: python experiments/seed000_vibration.py [configs/seed000_vibration.yaml] [--out DIR]
"""

import pathlib
import sys
from typing import Annotated

import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jflex  # noqa: E402
from pydantic import BaseModel, ConfigDict, Field  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent


class _Spring(jflex.effects.AbstractEffect):
    """1/2 k x^2 on the slider coordinate (a one-line effect; the library has no bare spring)."""

    k: jnp.ndarray

    def potential_energy(self, robot, slots, x):
        return 0.5 * self.k * x[0] ** 2


def oscillator(m, k, c):
    robot = jflex.make_robot(
        joint_names=["s"], link_names=["mass"], parents=[-1], joint_types=["prismatic"],
        placement_R=np.eye(3)[None], placement_p=np.zeros((1, 3)), axis=[[1.0, 0, 0]],
        inertia=np.array([[m] + [0.0] * 9]), gravity=(0, 0, 0),
    )
    return jflex.Model(robot, [_Spring(jnp.asarray(k)), jflex.effects.ViscousDamping((0,), [c])])


def free_closed_form(m, k, c, x0, v0, t):
    wn = np.sqrt(k / m)
    z = c / (2 * np.sqrt(k * m))
    if z < 1:
        wd = wn * np.sqrt(1 - z**2)
        return np.exp(-z * wn * t) * (x0 * np.cos(wd * t) + (v0 + z * wn * x0) / wd * np.sin(wd * t))
    if np.isclose(z, 1.0):
        return np.exp(-wn * t) * (x0 + (v0 + wn * x0) * t)
    s1, s2 = -wn * (z - np.sqrt(z**2 - 1)), -wn * (z + np.sqrt(z**2 - 1))
    A = (v0 - s2 * x0) / (s1 - s2)
    return A * np.exp(s1 * t) + (x0 - A) * np.exp(s2 * t)


def _stage(text):
    print(f"seed000_vibration: {text}", file=sys.stderr, flush=True)


def run(cfg, out):
    m, k = float(cfg["mass_kg"]), float(cfg["stiffness_N_per_m"])
    wn = np.sqrt(k / m)
    tol = dict(rtol=float(cfg["rtol"]), atol=float(cfg["atol"]))
    ts = np.linspace(0, float(cfg["t_end_s"]), int(cfg["samples"]))
    res = {"natural_frequency_rad_per_s": wn, "free": []}

    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    _stage(f"free responses ({len(cfg['damping_ratios'])} damping ratios)")
    for z in cfg["damping_ratios"]:
        c = 2 * z * np.sqrt(k * m)
        r = jflex.simulate(oscillator(m, k, c), ts, x0=[cfg["x0_m"]], xd0=[cfg["v0_m_per_s"]], outputs=("s",), **tol)
        ref = free_closed_form(m, k, c, cfg["x0_m"], cfg["v0_m_per_s"], ts)
        err = float(np.max(np.abs(np.asarray(r["s"]) - ref)))
        res["free"].append({"damping_ratio": z, "max_error_m": err})
        ax[0].plot(ts, 1e3 * np.asarray(r["s"]), label=f"zeta = {z} (max err {err:.1e} m)")
        ax[0].plot(ts, 1e3 * ref, "k:", lw=0.8)
    ax[0].set(xlabel="t [s]", ylabel="x [mm]", title="free responses (dotted: closed form)")
    ax[0].legend(fontsize=7)

    fc = cfg["forced"]
    z, F = float(fc["damping_ratio"]), float(fc["force_N"])
    c = 2 * z * np.sqrt(k * m)
    rows = []
    _stage(f"forced steady states ({len(fc['frequency_ratios'])} frequencies)")
    for ratio in fc["frequency_ratios"]:
        w = ratio * wn
        T = 2 * np.pi / w
        t_settle = fc["settle_periods"] * max(T, 2 * np.pi / wn)
        ts_f = np.linspace(t_settle, t_settle + 3 * T, 301)
        u = jflex.Chirp([F], w / (2 * np.pi), w / (2 * np.pi), duration=t_settle + 4 * T)
        r = jflex.simulate(oscillator(m, k, c), ts_f, inputs=u, t0=0.0, outputs=("s",), max_steps=400_000, **tol)
        x = np.asarray(r["s"])
        # least-squares fit of X sin(w t - phi) to the last three periods
        A = np.stack([np.sin(w * ts_f), np.cos(w * ts_f)], 1)
        a, b = np.linalg.lstsq(A, x, rcond=None)[0]
        X, phi = np.hypot(a, b), np.arctan2(-b, a)
        X_ref = F / np.sqrt((k - m * w**2) ** 2 + (c * w) ** 2)
        phi_ref = np.arctan2(c * w, k - m * w**2)
        rows.append({"frequency_ratio": ratio, "amplitude_m": X, "amplitude_closed_form_m": X_ref,
                     "phase_rad": phi, "phase_closed_form_rad": phi_ref})
    res["forced_steady_state"] = rows
    r_ = np.linspace(0.05, 3, 300)
    ax[1].plot(r_, 1 / np.sqrt((1 - r_**2) ** 2 + (2 * z * r_) ** 2), "k-", label="closed form X k / F")
    ax[1].plot([q["frequency_ratio"] for q in rows], [q["amplitude_m"] * k / F for q in rows], "o", label="simulated")
    ax[1].set(xlabel="omega / omega_n", ylabel="X k / F", yscale="log", title=f"forced, zeta = {z}")
    ax[1].legend()

    _stage("half-sine pulse against the Duhamel integral")
    dc = cfg["duhamel"]
    z, P0, tp = float(dc["damping_ratio"]), float(dc["pulse_N"]), float(dc["pulse_duration_s"])
    c = 2 * z * np.sqrt(k * m)
    ts_d = np.linspace(0, 1.0, 4001)
    pulse = jflex.Function(lambda t: jnp.where(t < tp, P0 * jnp.sin(jnp.pi * t / tp), 0.0)[None], jumps=(tp,))
    r = jflex.simulate(oscillator(m, k, c), ts_d, inputs=pulse, outputs=("s",), **tol)
    wd = wn * np.sqrt(1 - z**2)
    Fs = np.where(ts_d < tp, P0 * np.sin(np.pi * ts_d / tp), 0.0)
    h = np.exp(-z * wn * ts_d) * np.sin(wd * ts_d) / (m * wd)
    duh = np.array([np.trapezoid(Fs[: i + 1] * h[i::-1], ts_d[: i + 1]) for i in range(ts_d.size)])
    res["duhamel_half_sine"] = {"max_abs_difference_m": float(np.max(np.abs(np.asarray(r["s"]) - duh))),
                                "peak_response_m": float(np.max(np.abs(duh)))}
    ax[2].plot(ts_d, 1e3 * np.asarray(r["s"]), label="jflex.simulate")
    ax[2].plot(ts_d, 1e3 * duh, "k:", label="Duhamel integral")
    ax[2].set(xlabel="t [s]", ylabel="x [mm]", title="half-sine pulse")
    ax[2].legend()
    fig.tight_layout()
    fig.savefig(out / "seed000_responses.png", dpi=120)
    return res


# --- the config's schema (jflex.experiment_cli validates the YAML against it) ------------------------
class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


Positive = Annotated[float, Field(gt=0)]
Ratio = Annotated[float, Field(ge=0)]


class ForcedConfig(_Strict):
    force_N: float = Field(description="harmonic force amplitude [N]")
    frequency_ratios: Annotated[list[Positive], Field(min_length=1)] = Field(description="omega / omega_n")
    damping_ratio: Ratio
    settle_periods: Positive = Field(description="periods simulated before the fitted three")


class DuhamelConfig(_Strict):
    damping_ratio: Annotated[float, Field(ge=0, lt=1)] = Field(description="underdamped: the impulse response uses omega_d")
    pulse_N: float = Field(description="half-sine pulse amplitude [N]")
    pulse_duration_s: Positive


class Seed000VibrationConfig(_Strict):
    mass_kg: Positive
    stiffness_N_per_m: Positive
    damping_ratios: Annotated[list[Ratio], Field(min_length=1)] = Field(description="free responses, one per ratio")
    x0_m: float
    v0_m_per_s: float
    t_end_s: Positive
    samples: Annotated[int, Field(ge=2)]
    forced: ForcedConfig
    duhamel: DuhamelConfig
    rtol: Positive
    atol: Positive


def quick_figures(res) -> dict:
    """The key figures of ``--quick`` against the closed forms, loosely (x0 = 10 mm)."""
    amp = max(abs(f["amplitude_m"] / f["amplitude_closed_form_m"] - 1) for f in res["forced_steady_state"])
    phase = max(abs(f["phase_rad"] - f["phase_closed_form_rad"]) for f in res["forced_steady_state"])
    duh = res["duhamel_half_sine"]
    return {
        "free response, max error [m]": (max(f["max_error_m"] for f in res["free"]), 0.0, 1e-6),
        "forced amplitude, max relative error": (amp, 0.0, 1e-3),
        "forced phase, max error [rad]": (phase, 0.0, 1e-3),
        "Duhamel half sine, max difference / peak": (duh["max_abs_difference_m"] / duh["peak_response_m"], 0.0, 1e-3),
    }


def main(argv=None):
    return jflex.experiment_cli("seed000_vibration", HERE.parent / "configs" / "seed000_vibration.yaml", run, argv,
                                schema=Seed000VibrationConfig,
                                quick=(HERE.parent / "configs" / "seed000_vibration_quick.yaml", quick_figures))


if __name__ == "__main__":
    main(sys.argv[1:])
