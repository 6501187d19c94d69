"""Seed 001: the single-link revolute-prismatic arm of Table 3 (flexible link sliding through a
flexible hub, flexible revolute joint) in the four variants F.L-R.H, F.L-F.H, F.L-F.H-F.J and
F.L-R.H-F.J, under a constant revolute torque, +/- prismatic force steps and a brake.

Usage: python experiments/seed001_rp_arm.py [configs/seed001_rp_arm_quick.yaml] [--out DIR]
(configs/seed001_rp_arm.yaml: two hub modes as in the paper, about ten times the CPU time)
"""

import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import jflex  # noqa: E402
from jflex.effects import FlexibleJoints, FlexibleLink, KelvinVoigt  # noqa: E402

HERE = pathlib.Path(__file__).resolve().parent


def _rod(mu, a, b):
    """Inertial parameters of a thin rod of mass per length ``mu`` on [a, b] along body x."""
    m, Izz = mu * (b - a), mu * (b**3 - a**3) / 3
    return [m, m * (a + b) / 2, 0, 0, 1e-9, 0, Izz, 0, 0, Izz]


def build(cfg, variant):
    lk, hb, jt = cfg["link"], cfg["hub"], cfg["joint"]
    Lh, L1, l0 = float(hb["length_m"]), float(lk["length_m"]), float(lk["free_length_at_start_m"])
    # the robot carries the rigid hub and the whole link as rigid rods (include_rigid=False below):
    # the link's material spans [Lh + l0 - L1, Lh + l0] of the prismatic body frame
    robot = jflex.make_robot(
        joint_names=["rev", "pri"], link_names=["hub", "link"], parents=[-1, 0], joint_types=["revolute", "prismatic"],
        placement_R=np.stack([np.eye(3)] * 2), placement_p=np.zeros((2, 3)), axis=[[0, 0, 1.0], [1.0, 0, 0]],
        inertia=np.array([_rod(hb["mass_per_length_kg_per_m"], 0.0, Lh),
                          _rod(lk["mass_per_length_kg_per_m"], Lh + l0 - L1, Lh + l0)]),
        gravity=(0, 0, -float(cfg["gravity_m_per_s2"])),
    )
    EI = float(lk["E_Pa"]) * float(lk["width_m"]) * float(lk["thickness_m"]) ** 3 / 12
    EIh = float(hb["E_Pa"]) * float(hb["width_m"]) * float(hb["thickness_m"]) ** 3 / 12
    link = jflex.make_beam(l0, float(lk["mass_per_length_kg_per_m"]), EI, int(lk["modes"]))
    kv = KelvinVoigt(float(lk["kelvin_voigt_Pa_s"]) / float(lk["E_Pa"]))
    flex_hub = "F.H" in variant
    hub = jflex.make_beam(Lh, float(hb["mass_per_length_kg_per_m"]), EIh, int(hb["modes"])) if flex_hub else None
    eff = FlexibleLink(
        "hub", link, root=(0.0, 0.0, 0.0) if flex_hub else (Lh, 0.0, 0.0), name="arm", sliding_joint="pri",
        hub=hub, include_rigid=False, air=float(lk["air_damping_kg_per_s_m"]), damping=kv,
        hub_damping=KelvinVoigt(float(hb["kelvin_voigt_Pa_s"]) / float(hb["E_Pa"])) if flex_hub else None,
        thickness=float(lk["thickness_m"]),
    )
    effects = [eff]
    if variant.endswith("F.J"):
        effects.append(FlexibleJoints([float(jt["stiffness_N_m_per_rad"])], rotor_inertia=[float(jt["motor_inertia_kg_m2"])],
                                      joints=[0], coupling=False))
    return jflex.Model(robot, effects), {"EI_link_N_m2": EI, "EI_hub_N_m2": EIh}


def inputs(cfg):
    ld = cfg["loading"]
    tb, ts_ = float(ld["brake_time_s"]), float(ld["prismatic_switch_s"])
    tau, F = float(ld["revolute_torque_N_m"]), float(ld["prismatic_force_N"])
    return (jflex.Step([tau, 0.0], 0.0, tb) + jflex.Brake([float(ld["brake_torque_N_m"]), 0.0], tb, tb + float(ld["brake_duration_s"]))
            + jflex.Step([0.0, F], 0.0, ts_) + jflex.Step([0.0, -F], ts_, tb))


def run(cfg, out):
    ts = np.linspace(0, float(cfg["t_end_s"]), int(cfg["samples"]))
    tol = dict(rtol=float(cfg["rtol"]), atol=float(cfg["atol"]))
    res = {"filled_values": {"loading": cfg["loading"], "plane": "horizontal (gravity along the revolute axis)",
                             "hub_kelvin_voigt_Pa_s": cfg["hub"]["kelvin_voigt_Pa_s"]}, "variants": {}}
    fig, ax = plt.subplots(3, 2, figsize=(13, 10))
    ax = ax.ravel()
    for v in cfg["variants"]:
        model, info = build(cfg, v)
        res.update(info)
        names = ["rev", "pri", "arm.eta1", "arm.eta2", "arm.tip_deflection", "arm.length", "arm.strain@0.05"]
        if "F.H" in v:
            names += ["arm.hub_eta1", "arm.hub_tip_deflection"]
        if v.endswith("F.J"):
            names += ["theta_rev"]
        print(f"seed001: simulating {v} ({model.nx} coordinates) ...", flush=True)
        r = jflex.simulate(model, ts, inputs=inputs(cfg), outputs=tuple(names), max_steps=500_000, **tol)
        o = {n: np.asarray(r[n]) for n in names}
        q1 = np.degrees(o["rev"])
        res["variants"][v] = {
            "q1_final_deg": q1[-1], "q1_mean_deg": q1.mean(), "q1_std_deg": q1.std(),
            "free_length_range_m": [o["arm.length"].min(), o["arm.length"].max()],
            "free_length_mean_mm": 1e3 * o["arm.length"].mean(), "free_length_std_mm": 1e3 * o["arm.length"].std(),
            "max_tip_deflection_mm": 1e3 * np.max(np.abs(o["arm.tip_deflection"])),
            "max_link_eta1_mm": 1e3 * np.max(np.abs(o["arm.eta1"])),
            "max_hub_eta1_mm": 1e3 * np.max(np.abs(o["arm.hub_eta1"])) if "F.H" in v else 0.0,
            "max_strain_at_5cm": np.max(np.abs(o["arm.strain@0.05"])),
            "solver_steps": int(r.num_steps),
        }
        ax[0].plot(ts, q1, label=v)
        ax[1].plot(ts, 1e3 * o["arm.length"], label=v)
        ax[2].plot(ts, 1e3 * o["arm.eta1"], label=v)
        ax[3].plot(ts, 1e3 * o["arm.tip_deflection"], label=v)
        if "F.H" in v:
            ax[4].plot(ts, 1e6 * o["arm.hub_eta1"], label=v)
        if v.endswith("F.J"):
            ax[5].plot(ts, np.degrees(o["rev"] - o["theta_rev"]), label=v)
    titles = [("revolute joint q1 [deg]", "Fig. 8"), ("free link length l [mm]", "Fig. 14"),
              ("link first modal coordinate [mm]", "Fig. 10"), ("tip deflection [mm]", "Fig. 16-17"),
              ("hub first modal coordinate [um]", "Fig. 12"), ("joint deflection q1 - theta [deg]", "")]
    for a, (t, f) in zip(ax, titles):
        a.set(xlabel="t [s]", title=f"{t} {('(cf. ' + f + ')') if f else ''}")
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "seed001_variants.png", dpi=120)
    res["table5_experiment_reference"] = {"q1_mean_deg": 45.895, "q1_std_deg": 28.454, "eta1_mean_mm": 378.843, "eta1_std_mm": 23.615}
    return res


def main(argv=None):
    return jflex.experiment_cli("seed001_rp_arm", HERE.parent / "configs" / "seed001_rp_arm_quick.yaml", run, argv)


if __name__ == "__main__":
    main(sys.argv[1:])
