"""Seed 003: identify joint K and C of the Staubli TX200 and Kuka KR90 from the modal tables.

The thesis matched K and C0 by hand to the configuration-1 modes (Tables 4.3/4.4) and predicted
configurations 2 and 3 (Tables 4.5/4.6: mean errors 5.47 % / 1.1 points for the Staubli,
12.8 % / 0.28 points for the Kuka). Here the same rigid-link flexible-joint model (base
parameters of Tables 3.3/3.6 realised as link inertias, rotors held) is fitted with
``jflex.identify.fit`` to the configuration-1 "Exp." frequencies and damping ratios, then to all
three configurations together, and the prediction errors are reported beside the thesis'.

    python experiments/identify_seed003.py [CONFIG] [--out DIR]
"""

from __future__ import annotations

import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import jflex
from jflex import identify as idf

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT = ROOT / "configs" / "identify_seed003.yaml"


# --- the seed-003 model: jflex.Seed003Robot (shared with posture_modal and gap_seed003) ---------
class Seed003(jflex.Seed003Robot):
    def __init__(self, path: pathlib.Path):
        cfg = jflex.load_yaml(path)
        super().__init__(cfg, path.parent)

    def gear_ratio(self, hold):
        """One common ratio reproducing the thesis' Model frequencies at configuration 1."""
        return self.fit_common_ratio(0, (20.0, 600.0), hold)


def tracked_order(model, postures, hold, steps):
    """Per posture, the model-mode indices that continue modes 1..3 of configuration 1 (by MAC
    along straight joint paths), as the thesis' tables pair modes by shape."""
    out = [list(range(3))]
    for q in postures[1:]:
        s = np.linspace(0, 1, steps)[:, None]
        path = (1 - s) * postures[0] + s * q
        shapes = np.stack([np.asarray(jflex.modal_analysis(model, p, hold=hold).shape) for p in path])
        perm, _ = jflex.track_modes(shapes)
        out.append([int(i) for i in np.asarray(perm[-1])])
    return np.array(out)


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
    steps = int(cfg.get("tracking_steps", 30))
    w = cfg.get("weights", {})
    results = {"hold": hold, "robots": {}}
    fig, axes = plt.subplots(2, 2, figsize=(11, 8))
    for row, rel in enumerate(cfg["robots"]):
        rob = Seed003(ROOT / "configs" / rel)
        r, r_err = rob.gear_ratio(hold)
        ratios = np.full(3, r)
        th = rob.thesis
        start = rob.model(ratios, rob.K * cfg.get("start_factor", 1.0), rob.C * cfg.get("start_factor", 1.0))
        spec = idf.ParameterSpec([idf.Free("K_N_m_per_rad", lambda m: m.effects[0].stiffness, transform=idf.Log()),
                                  idf.Free("C_N_m_s_per_rad", lambda m: m.effects[0].damping, transform=idf.Log())])
        out = {"gear_ratio": r, "gear_ratio_rms_error_to_thesis_model": r_err, "thesis": thesis_errors(th),
               "thesis_K_N_m_per_rad": rob.K.tolist(), "thesis_C_N_m_s_per_rad": rob.C.tolist()}
        model = start
        for label, configs in (("config1", list(cfg.get("identify_on", [0]))), ("all_configs", [0, 1, 2])):
            # Pair model modes with the table rows by shape (MAC tracking from configuration 1)
            # at the current parameters; the all-configurations fit starts from the first fit.
            order = tracked_order(model, rob.postures, hold, steps)
            data = idf.ModalData(rob.postures[configs], th["frequency_exp_Hz"][configs], th["damping_exp_pct"][configs] / 100,
                                 mode_index=order[configs], hold=hold, weights=(w.get("frequency", 1.0), w.get("damping", 1.0), 0.0),
                                 name=label)
            res = idf.fit(model, spec, data, max_steps=int(cfg.get("max_steps", 100)), progress=10)
            m = model = res.model
            order_fit = tracked_order(m, rob.postures, hold, steps)
            modes = [jflex.modal_analysis(m, q, hold=hold) for q in rob.postures]
            f = np.array([np.asarray(md.frequency)[o] for md, o in zip(modes, order_fit)])
            z = np.array([np.asarray(md.damping_ratio)[o] for md, o in zip(modes, order_fit)])
            print(f"{rob.name} [{label}]: K = {np.round(res.values['K_N_m_per_rad'] / 1e6, 3)} 1e6 N m/rad, "
                  f"C = {np.round(res.values['C_N_m_s_per_rad'] / 1e3, 3)} 1e3 N m s/rad")
            out[label] = {"fit": res.to_dict(), "frequency_Hz": f, "damping_pct": 100 * z, "mode_order_fit": order,
                          "mode_order_after": order_fit, "pairing_changed": bool((order != order_fit).any()),
                          "errors": errors(f, z, th, configs)}
            print(f"   errors: {out[label]['errors']}")
        results["robots"][rob.name] = out
        ax = axes[row, 0]
        x = np.arange(9)
        ax.plot(x, th["frequency_exp_Hz"].ravel(), "ko", label="EMA (Exp.)")
        ax.plot(x, th["frequency_model_Hz"].ravel(), "s", mfc="none", label="thesis model (manual K, C)")
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


def main(argv=None):
    return jflex.experiment_cli("identify_seed003", DEFAULT, run, argv, description=__doc__)


if __name__ == "__main__":
    main()
