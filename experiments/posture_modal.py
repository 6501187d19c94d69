"""Posture-dependent modal analysis of a Staubli TX200 and a Kuka KR90: modal tables, frequency maps, FRFs, lobes.

The robots (kinematics, identified base parameters, joint K and C) and the measured tables are
those of the MASc thesis "Posture Dependent Dynamics in Robotic Machining"; table, figure and equation numbers below are that thesis'.

For each robot: rigid core from the DH table plus a link-parameter realisation of the identified
base parameters (Appendix B's M(q) and G(q), checked against jflex's own regressor), flexible
joints with Table 4.3/4.4 stiffness and damping, the gravity compensator of Eq. 2.11, motors held.
Writes into one run folder: the modal table beside the thesis' Exp. and Model columns (a), maps
of the first three natural frequencies over (q2, q3) (b), tool FRFs (c), stability lobes (d).

    python experiments/posture_modal.py [configs/posture_modal.yaml] [--out DIR]
"""

from __future__ import annotations

import itertools
import pathlib
import sys
from typing import Annotated

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

import jflex

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT = ROOT / "configs" / "posture_modal.yaml"


# --- the config's schema (jflex.experiment_cli validates the YAML against it) ------------------------
class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


Count = Annotated[int, Field(ge=1)]


class MapConfig(_Strict):
    n_q2: Annotated[int, Field(ge=2)] = Field(description="grid points over q2")
    n_q3: Annotated[int, Field(ge=2)] = Field(description="grid points over q3")
    chunk_size: Count = Field(1024, description="postures per compiled batch")


class FrfConfig(_Strict):
    f_min_Hz: Annotated[float, Field(gt=0)]
    f_max_Hz: Annotated[float, Field(gt=0)]
    n: Annotated[int, Field(ge=2)]

    @model_validator(mode="after")
    def _band(self):
        if self.f_max_Hz <= self.f_min_Hz:
            raise ValueError(f"f_max_Hz ({self.f_max_Hz}) must exceed f_min_Hz ({self.f_min_Hz})")
        return self


class LobesConfig(_Strict):
    robot: str = Field(description="name of one of the robots")
    postures: Annotated[list[Annotated[int, Field(ge=0)]], Field(min_length=1)]
    cutting_axes: Annotated[list[Annotated[list[float], Field(min_length=3, max_length=3)]],
                            Field(min_length=3, max_length=3)] = Field(description="feed, normal, tool axis as rows")
    spindle_rpm: Annotated[list[Annotated[float, Field(gt=0)]], Field(min_length=2, max_length=2)]
    n_lobes: Count


class PostureModalConfig(_Strict):
    robots: Annotated[list[str], Field(min_length=1)] = Field(description="robot configs with identified dynamics (seed003/*.yaml), relative to configs/")
    milling: str = Field(description="milling parameters (Table 4.7), relative to configs/")
    hold: str | list[str] = Field("actuated", description="coordinates held (jflex.modal_analysis)")
    tool_frame: str = "tool"
    tracking_steps: Count | None = Field(None, description="unused (rows are paired by shape with configuration 1); kept so older configs validate")
    map: MapConfig
    frf: FrfConfig
    lobes: LobesConfig


# the thesis' robots (DH, base parameters, flexible joints, EMA postures): a sibling module of the
# experiments (their folder is no package in a checkout)
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _machining_robot import MachiningRobot  # noqa: E402


def modal_table(rob: MachiningRobot, model, hold, frame):
    """Modes at the thesis postures, ordered like the thesis rows: configuration 1 sorted by
    frequency (as in Tables 4.5/4.6), the others paired with configuration 1's mode shapes
    (:func:`jflex.linear.pair_modes`: MAC first, frequency as the tie-break), as the tables label
    rows by shape (one compiled batch for all postures)."""
    th = rob.thesis
    order, mac_c1, modes = rob.row_order(model, hold, frame)
    f_all, z_all = np.asarray(modes.frequency), np.asarray(modes.damping_ratio)
    rows = {"paired_by_shape": [], "matched_to_thesis_rows": []}
    tool_shapes = []
    for k in range(len(rob.postures)):
        perm, macs = order[k], mac_c1[k]
        # a cross-check that reads the answer: rows paired by closeness of (f, zeta) to the
        # thesis' Model column
        fm_all, zm_all = th["frequency_model_Hz"][k], th["damping_model_pct"][k]
        cands = [np.array(pp) for pp in itertools.permutations(range(3))]
        cost = [np.sum(np.abs(f_all[k][pp] - fm_all) / fm_all + np.abs(100 * z_all[k][pp] - zm_all) / zm_all) for pp in cands]
        matched = cands[int(np.argmin(cost))]
        tool_shapes.append(np.asarray(modes.tool_shape[k])[:, perm])
        for key, pm in (("paired_by_shape", perm), ("matched_to_thesis_rows", matched)):
            f = f_all[k][pm]
            z = 100 * z_all[k][pm]
            for i in range(3):
                fm, fx = fm_all[i], th["frequency_exp_Hz"][k, i]
                rows[key].append(
                    dict(
                        configuration=k + 1, mode=i + 1, jflex_mode_index=int(pm[i]) + 1,
                        frequency_jflex_Hz=f[i], frequency_thesis_model_Hz=fm, frequency_exp_Hz=fx,
                        damping_jflex_pct=z[i], damping_thesis_model_pct=zm_all[i],
                        damping_exp_pct=th["damping_exp_pct"][k, i],
                        error_to_model_pct=100 * (f[i] - fm) / fm, error_to_exp_pct=100 * (f[i] - fx) / fx,
                        mac_to_configuration1=float(macs[i]),
                    )
                )
    return rows, tool_shapes


def summarise(rows):
    e_m = np.array([abs(r["error_to_model_pct"]) for r in rows])
    e_x = np.array([abs(r["error_to_exp_pct"]) for r in rows])
    thesis = np.array([abs(r["frequency_thesis_model_Hz"] - r["frequency_exp_Hz"]) / r["frequency_exp_Hz"] for r in rows])
    dz_m = np.array([abs(r["damping_jflex_pct"] - r["damping_thesis_model_pct"]) for r in rows])
    dz_x = np.array([abs(r["damping_jflex_pct"] - r["damping_exp_pct"]) for r in rows])
    return dict(
        mean_abs_frequency_error_to_thesis_model_pct=e_m.mean(),
        max_abs_frequency_error_to_thesis_model_pct=e_m.max(),
        mean_abs_frequency_error_to_exp_pct=e_x.mean(),
        thesis_model_vs_exp_mean_frequency_error_pct=100 * thesis.mean(),
        mean_abs_damping_difference_to_thesis_model_pct_points=dz_m.mean(),
        mean_abs_damping_difference_to_exp_pct_points=dz_x.mean(),
    )


def frequency_map(rob, model, q1, n2, n3, hold, chunk, out_dir):
    (a2, b2), (a3, b3) = np.radians(np.asarray(rob.cfg["map_range_deg"], dtype=float))
    q2, q3 = np.linspace(a2, b2, n2), np.linspace(a3, b3, n3)
    Q2, Q3 = np.meshgrid(q2, q3, indexing="ij")
    order = jflex.linear.serpentine(n2, n3)
    flat = np.stack([np.full(Q2.size, q1), Q2.ravel(), Q3.ravel()], axis=1)[order]

    def one(q):
        m = jflex.modal_analysis(model, q, hold=hold)
        return m.frequency, m.damping_ratio, m.shape

    f, z, shapes = jflex.sweep(one, flat, chunk_size=chunk, out_dir=out_dir, label=f"map {rob.name}")
    perm, cont = jflex.track_modes(shapes)
    perm = np.asarray(perm)
    f_t = np.take_along_axis(f, perm, axis=1)
    inv = np.empty_like(order)
    inv[order] = np.arange(order.size)
    f_t, f_s = f_t[inv].reshape(n2, n3, -1), f[inv].reshape(n2, n3, -1)
    return q2, q3, f_s, f_t, float(np.min(cont))


def _caption(fig, rob, what: str):
    """The source, cited once per figure, below it."""
    fig.text(0.5, 0.0, f"{what}. Model: jflex, {rob.cfg['source']}; reflected rotor inertias {rob.cfg['gear_ratios'].get('provenance', 'as configured')}.",
             ha="center", va="top", fontsize=8, wrap=True)


def plot_maps(path, rob, q2, q3, f_sorted, f_tracked):
    fig, axes = plt.subplots(2, 3, figsize=(14, 8), constrained_layout=True)
    for row, (F, lab) in enumerate([(f_sorted, "sorted"), (f_tracked, "MAC-tracked")]):
        for i in range(3):
            ax = axes[row, i]
            cs = ax.contourf(np.degrees(q3), np.degrees(q2), F[:, :, i], levels=20, cmap="viridis")
            fig.colorbar(cs, ax=ax, label="f [Hz]")
            ax.plot(np.degrees(rob.postures[:, 2]), np.degrees(rob.postures[:, 1]), "r^")
            for k, qk in enumerate(np.degrees(rob.postures)):
                ax.annotate(f"config. {k + 1}", (qk[2], qk[1]), color="r", fontsize=7, xytext=(3, 3), textcoords="offset points")
            ax.set_title(f"{rob.name}: mode {i + 1} ({lab}), q1 = {np.degrees(rob.postures[0, 0]):.0f} deg")
            ax.set_xlabel("q3 [deg]")
            ax.set_ylabel("q2 [deg]")
    _caption(fig, rob, f"{rob.name}: first three natural frequencies over (q2, q3), motors held; triangles: the EMA configurations 1-3")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_frfs(path, rob, omega, frfs):
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    for i, lab in enumerate("XYZ"):
        for k, G in enumerate(frfs):
            axes[i].semilogy(omega / (2 * np.pi), np.abs(G[:, i, i]), label=f"configuration {k + 1}")
        axes[i].set_title(f"{rob.name}: |G_{lab}{lab}| at the tool (tool axes)")
        axes[i].set_xlabel("f [Hz]")
        axes[i].set_ylabel("receptance [m/N]")
        axes[i].grid(True, which="both", alpha=0.3)
    axes[0].legend()
    _caption(fig, rob, f"{rob.name}: predicted tool receptance at the EMA configurations 1-3, motors held")
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def run(cfg: dict, run_dir: pathlib.Path) -> dict:
    cfg_root = ROOT / "configs"
    hold = cfg.get("hold", "actuated")
    frame = cfg.get("tool_frame", "tool")
    results: dict = {"hold": hold, "robots": {}}
    fr = cfg["frf"]
    omega = 2 * np.pi * np.linspace(fr["f_min_Hz"], fr["f_max_Hz"], int(fr["n"]))
    models, robs, frf_cache = {}, {}, {}
    for rel in cfg["robots"]:
        path = cfg_root / rel
        rob = MachiningRobot(jflex.load_yaml(path), path.parent)
        model, how = rob.configured_model()
        ratios = np.asarray(model.effects[0].gear_ratio)
        models[rob.name], robs[rob.name] = model, rob
        print(f"{rob.name}: {how}")

        rows, tool_shapes = modal_table(rob, model, hold, frame)
        summary = {key: summarise(v) for key, v in rows.items()}
        for key, sm in summary.items():
            print(f"{rob.name} [{key}]: " + ", ".join(f"{k} = {v:.2f}" for k, v in sm.items()))

        mp = cfg["map"]
        q2, q3, f_s, f_t, cmin = frequency_map(
            rob, model, float(rob.postures[0, 0]), int(mp["n_q2"]), int(mp["n_q3"]), hold, int(mp["chunk_size"]),
            run_dir / f"map_chunks_{rob.name}",
        )
        plot_maps(run_dir / f"frequency_maps_{rob.name}.png", rob, q2, q3, f_s, f_t)

        frfs = jflex.sweep(lambda q: jflex.frf(model, q, omega, hold=hold, frame=frame, reference="local"),
                           rob.postures, progress=False)
        frf_cache[rob.name] = frfs
        plot_frfs(run_dir / f"tool_frf_{rob.name}.png", rob, omega, frfs)
        # the half-power estimate of the dominant tool-Z peak against the modal damping ratio
        hp = [jflex.linear.half_power_damping(omega, G[:, 2, 2]) for G in frfs]

        results["robots"][rob.name] = {
            "gear_ratios": ratios.tolist(),
            "gear_ratio_choice": how,
            "reflected_rotor_inertia_kg_m2": (ratios**2 * np.asarray(model.effects[0].rotor_inertia)).tolist(),
            "rotor_inertia_kg_m2": np.asarray(model.effects[0].rotor_inertia).tolist(),
            "base_parameter_realisation_rel_error": float(np.max(rob.realisation_error)),
            "modal_table": rows,
            "tool_mode_shapes_local_axes": tool_shapes,
            "summary": summary,
            "thesis_reported_mean_frequency_error_pct": rob.thesis["mean_frequency_error_pct"],
            "map": {
                "q2_deg": np.degrees(q2), "q3_deg": np.degrees(q3), "q1_deg": float(np.degrees(rob.postures[0, 0])),
                "frequency_range_Hz": [np.nanmin(f_s, axis=(0, 1)), np.nanmax(f_s, axis=(0, 1))],
                "tracking_min_mac": cmin,
                "n_nonfinite": int(np.sum(~np.isfinite(f_s))),
            },
            "tool_frf_half_power_zz": [
                {"configuration": k + 1, "zeta_half_power": float(z), "peak_Hz": float(w) / (2 * np.pi)} for k, (z, w) in enumerate(hp)
            ],
        }

    # (d) stability lobes
    lb = cfg["lobes"]
    mill = jflex.load_yaml(cfg_root / cfg["milling"])
    rob, model = robs[lb["robot"]], models[lb["robot"]]
    Rc = np.asarray(lb["cutting_axes"], dtype=float)
    phi_st, phi_ex = jflex.linear.immersion_angles(mill["radial_immersion"], mill["mode"])
    rpm = np.linspace(*lb["spindle_rpm"], 2000)
    fig, ax = plt.subplots(figsize=(9, 5), constrained_layout=True)
    lobes_out = []
    for k in lb["postures"]:
        G = frf_cache[lb["robot"]][k]
        Gc = np.einsum("ij,fjk,lk->fil", Rc, G, Rc)
        lobes = jflex.stability_lobes(
            Gc, omega, n_teeth=int(mill["n_teeth"]), Kt=mill["Kt"], Kr=mill["Kr"], Ka=mill["Ka"],
            lead_angle=np.radians(mill["lead_angle_deg"]), phi_start=phi_st, phi_exit=phi_ex, n_lobes=int(lb["n_lobes"]),
        )
        lim = jflex.linear.stability_limit(lobes, rpm)
        ax.plot(rpm, 1e3 * lim, label=f"{rob.name} configuration {k + 1}")
        lobes_out.append({
            "configuration": k + 1,
            "min_stable_depth_mm": float(1e3 * np.nanmin(np.asarray(lobes.depth))),
            "spindle_rpm": rpm, "stable_depth_mm": 1e3 * lim,
        })
    ax.set_xlabel("spindle speed [rpm]")
    ax.set_ylabel("axial depth limit [mm]")
    ax.set_title(f"{rob.name}: ZOA stability lobes from the predicted tool FRF")
    ax.grid(True, alpha=0.3)
    ax.legend()
    _caption(fig, rob, f"{rob.name}: stability limits at configurations {', '.join(str(k + 1) for k in lb['postures'])}; "
             f"milling parameters of Table 4.7 of the MASc thesis \"Posture Dependent Dynamics in Robotic Machining\"")
    fig.savefig(run_dir / "stability_lobes.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    results["stability_lobes"] = {"robot": lb["robot"], "postures": lobes_out}
    return results


def quick_figures(res) -> dict:
    """The key figures of ``--quick``, loosely: every mode of every configuration within 1.5 % of
    the thesis' Model column (Tables 4.5, 4.6; 1 % in the full run), a frequency map without
    holes, and a finite positive stability limit at each configuration."""
    out = {}
    for name, r in res["robots"].items():
        for key, sm in r["summary"].items():
            out[f"{name} [{key}]: max |frequency error| to the thesis model [%]"] = (
                sm["max_abs_frequency_error_to_thesis_model_pct"], 0.0, 1.5)
        out[f"{name}: non-finite frequencies in the map"] = (r["map"]["n_nonfinite"], 0, 0)
    for lb in res["stability_lobes"]["postures"]:
        out[f"configuration {lb['configuration']}: min stable depth [mm]"] = (lb["min_stable_depth_mm"], 1e-3, 1e3)
    return out


def main(argv=None):
    return jflex.experiment_cli("posture_modal", DEFAULT, run, argv, description=__doc__, schema=PostureModalConfig,
                                quick=(DEFAULT.with_name("posture_modal_quick.yaml"), quick_figures))


if __name__ == "__main__":
    main(sys.argv[1:])
