"""Joint stiffness K and damping C of a Staubli TX200 and a Kuka KR90 identified from measured modal tables.

The robots, tables and the manually tuned K, C compared against are those of the MASc thesis "Posture Dependent Dynamics in Robotic Machining".

The thesis matched K and C0 by hand to the configuration-1 modes (Tables 4.3/4.4) and predicted
configurations 2 and 3 (Tables 4.5/4.6: mean errors 5.47 % / 1.1 points for the Staubli,
12.8 % / 0.28 points for the Kuka). Here the same rigid-link flexible-joint model (base
parameters of Tables 3.3/3.6 realised as link inertias, rotors held) is fitted with
``jflex.identify.fit`` to the configuration-1 "Exp." frequencies and damping ratios, then to all
three configurations together, and the prediction errors are reported beside the thesis'.
The thesis averages differently per robot: 5.47 % (Staubli) over all nine rows, 12.8 % (Kuka) over
configurations 2-3. Model modes are paired with the table rows by shape likeness to configuration 1
(``MachiningRobot.row_order``, :func:`jflex.linear.pair_modes`); the rotors are the config's per-joint
reflected inertias.

    python experiments/identify_seed003.py [CONFIG] [--out DIR]
"""

from __future__ import annotations

import pathlib
import sys
from typing import Annotated

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

import jflex
from jflex import identify as idf

# the thesis' robots: a sibling module of the experiments (their folder is no package in a checkout)
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _machining_robot import MachiningRobot  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT = ROOT / "configs" / "identify_seed003.yaml"


# --- the config's schema (jflex.experiment_cli validates the YAML against it) ------------------------
class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


Positive = Annotated[float, Field(gt=0)]


class Weights(_Strict):
    frequency: Annotated[float, Field(ge=0)] = Field(1.0, description="weight of 1 % frequency error")
    damping: Annotated[float, Field(ge=0)] = Field(1.0, description="weight of 1 damping-ratio point")


class IdentifySeed003Config(_Strict):
    robots: Annotated[list[str], Field(min_length=1)] = Field(description="robot configs with identified dynamics (seed003/*.yaml), relative to configs/")
    hold: str | list[str] = Field("actuated", description="coordinates held (jflex.modal_analysis)")
    tracking_steps: Annotated[int, Field(ge=1)] | None = Field(
        None, description="unused (rows are paired by shape with configuration 1); kept so older configs validate")
    identify_on: Annotated[list[Annotated[int, Field(ge=0, le=2)]], Field(min_length=1, max_length=3)] = Field(
        [0], description="configurations of the first fit (0 = configuration 1)")
    start_factor: Positive = Field(1.0, description="start at the thesis' K, C times this factor")
    weights: Weights = Field(default_factory=Weights)
    max_steps: Annotated[int, Field(ge=1)] = 100


# --- the thesis' model: _machining_robot.MachiningRobot (shared with posture_modal, seed003_prediction, gap_seed003)


def errors(f, z, th, configs):
    fe, ze = th["frequency_exp_Hz"], th["damping_exp_pct"] / 100
    ef = np.abs(f - fe) / fe * 100
    ez = np.abs(z - ze) * 100
    return {
        "mean_frequency_error_all_pct": float(ef.mean()),
        "mean_damping_error_all_pct_points": float(ez.mean()),
        "mean_frequency_error_predicted_pct": float(ef[[c for c in range(3) if c not in configs]].mean()) if len(configs) < 3 else None,
        "mean_damping_error_predicted_pct_points": float(ez[[c for c in range(3) if c not in configs]].mean()) if len(configs) < 3 else None,
    }


def thesis_errors(th):
    fe, fm = th["frequency_exp_Hz"], th["frequency_model_Hz"]
    ze, zm = th["damping_exp_pct"], th["damping_model_pct"]
    ef, ez = np.abs(fm - fe) / fe * 100, np.abs(zm - ze)
    return {"mean_frequency_error_all_pct": float(ef.mean()), "mean_damping_error_all_pct_points": float(ez.mean()),
            "mean_frequency_error_predicted_pct": float(ef[1:].mean()), "mean_damping_error_predicted_pct_points": float(ez[1:].mean()),
            "reported_mean_frequency_error_pct": th["mean_frequency_error_pct"]}


def run(cfg: dict, run_dir: pathlib.Path) -> dict:
    hold = cfg.get("hold", "actuated")
    w = cfg.get("weights", {})
    results = {"hold": hold, "mode_pairing": "jflex.linear.pair_modes with configuration 1's shapes (MAC, frequency tie-break)",
               "robots": {}}
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    for row, rel in enumerate(cfg["robots"]):
        rob = MachiningRobot.from_config(ROOT / "configs" / rel)
        th = rob.thesis
        start, how = rob.configured_model(rob.K * cfg.get("start_factor", 1.0), rob.C * cfg.get("start_factor", 1.0))
        spec = idf.ParameterSpec([idf.Free("K_N_m_per_rad", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                                  idf.Free("C_N_m_s_per_rad", lambda m: m.effects[0].damping, transform=idf.Log())])
        out = {"rotor_model": how, "thesis": thesis_errors(th),
               "thesis_K_N_m_per_rad": rob.K.tolist(), "thesis_C_N_m_s_per_rad": rob.C.tolist()}
        model = start
        for label, configs in (("config1", list(cfg.get("identify_on", [0]))), ("all_configs", [0, 1, 2])):
            # Pair model modes with the table rows by shape (configuration 1's shapes) at the
            # current parameters; the all-configurations fit starts from the first fit.
            order, _, _ = rob.row_order(model, hold)
            data = idf.ModalData(rob.postures[configs], th["frequency_exp_Hz"][configs], th["damping_exp_pct"][configs] / 100,
                                 mode_index=order[configs], hold=hold, weights=(w.get("frequency", 1.0), w.get("damping", 1.0), 0.0),
                                 name=label)
            res = idf.fit(model, spec, data, max_steps=int(cfg.get("max_steps", 100)), progress=10)
            m = model = res.model
            order_fit, mac_fit, modes = rob.row_order(m, hold)
            f = np.take_along_axis(np.asarray(modes.frequency), order_fit, axis=1)
            z = np.take_along_axis(np.asarray(modes.damping_ratio), order_fit, axis=1)
            print(f"{rob.name} [{label}]: K = {np.round(res.values['K_N_m_per_rad'] / 1e6, 3)} 1e6 N m/rad, "
                  f"C = {np.round(res.values['C_N_m_s_per_rad'] / 1e3, 3)} 1e3 N m s/rad")
            out[label] = {"fit": res.to_dict(), "frequency_Hz": f, "damping_pct": 100 * z, "mode_order_fit": order,
                          "mode_order_after": order_fit, "mac_to_configuration1_after": mac_fit,
                          "pairing_changed": bool((order != order_fit).any()), "errors": errors(f, z, th, configs)}
            print(f"   errors: {out[label]['errors']}")
        results["robots"][rob.name] = out
        ax = axes[row, 0]
        x = np.arange(9)
        ax.plot(x, th["frequency_exp_Hz"].ravel(), "ko", label="EMA (Exp.)")
        ax.plot(x, th["frequency_model_Hz"].ravel(), "s", mfc="none", label="published model (K, C tuned by hand)")
        ax.plot(x, out["config1"]["frequency_Hz"].ravel(), "x", label="fit on config. 1")
        ax.plot(x, out["all_configs"]["frequency_Hz"].ravel(), "+", ms=10, label="fit on all configs")
        ax.set_ylabel("natural frequency [Hz]")
        ax.set_title(rob.name)
        ax.set_xticks(x, [f"c{c + 1}m{k + 1}" for c in range(3) for k in range(3)])
        ax.legend(fontsize=7)
        ax = axes[row, 1]
        ax.plot(x, th["damping_exp_pct"].ravel(), "ko")
        ax.plot(x, th["damping_model_pct"].ravel(), "s", mfc="none")
        ax.plot(x, out["config1"]["damping_pct"].ravel(), "x")
        ax.plot(x, out["all_configs"]["damping_pct"].ravel(), "+", ms=10)
        ax.set_ylabel("damping ratio [%]")
        ax.set_xticks(x, [f"c{c + 1}m{k + 1}" for c in range(3) for k in range(3)])
    fig.tight_layout()
    fig.savefig(run_dir / "modal_fit.png", dpi=120)
    plt.close(fig)
    return results


def quick_figures(res) -> dict:
    """The key figures of ``--quick``, loosely: fitted on configuration 1, each robot predicts
    configurations 2-3 about as well as the thesis' hand-tuned K, C (mean frequency error within
    1.2 x the thesis': 7.68 % Staubli, 12.8 % Kuka), and the Staubli's fit on all three
    configurations stays within 1.2 x the thesis' mean over the nine rows (5.46 %)."""
    out = {}
    for name, r in res["robots"].items():
        th = r["thesis"]["mean_frequency_error_predicted_pct"]
        out[f"{name}, fit on configuration 1: mean frequency error predicted [%]"] = (
            r["config1"]["errors"]["mean_frequency_error_predicted_pct"], 0.0, 1.2 * th)
    st = res["robots"]["staubli_tx200"]
    out["staubli_tx200, fit on all: mean frequency error [%]"] = (
        st["all_configs"]["errors"]["mean_frequency_error_all_pct"], 0.0, 1.2 * st["thesis"]["mean_frequency_error_all_pct"])
    return out


def main(argv=None):
    return jflex.experiment_cli("identify_seed003", DEFAULT, run, argv, description=__doc__, schema=IdentifySeed003Config,
                                quick=(DEFAULT.with_name("identify_seed003_quick.yaml"), quick_figures))


if __name__ == "__main__":
    main(sys.argv[1:])
