"""Predicting held-out measured modes (EMA) of a Staubli TX200 and a Kuka KR90 from joint K, C fitted on others.

Robots, postures and measured tables are those of the MASc thesis "Posture Dependent Dynamics in Robotic Machining".

The thesis fitted joint K and C0 by hand on configuration 1 and predicted configurations 2-3
(Tables 4.5/4.6). Here, for each robot:

1. the model of ``configs/seed003/*.yaml`` (base parameters realised as links, per-joint reflected
   rotor inertias, gravity compensator, motors held) is written as a case folder and
   :func:`jflex.gap.diagnose` chooses effects on it (the Kuka's unmatched 19.2 Hz mode; for the
   Staubli the wrist joint q5 is a joint of the case, rigid in the nominal model, so that the
   diagnosis can test it as a flexible joint);
2. two models are fitted on each split of the configurations and predict the others: joint K, C
   only ("K,C refit"), and K, C plus the springs of the diagnosed effects ("K,C + diagnosed");
3. held-out frequency and damping errors per mode are set beside the thesis' own (its Model
   column against its Exp. column, the same rows), in results.json, ``prediction.md`` and one
   figure, with the singular values of each fit's Jacobian (what so few modes can identify).

Rows are paired as the thesis pairs them, by shape likeness to configuration 1
(``MachiningRobot.row_order``: :func:`jflex.linear.pair_modes`); held-out errors with the pairing by
nearest frequency (the diagnosis' rule) are reported beside.

    python experiments/seed003_prediction.py [configs/seed003_prediction.yaml] [--out DIR]
"""

from __future__ import annotations

import pathlib
import sys
from typing import Annotated

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import yaml
from pydantic import BaseModel, ConfigDict, Field
from scipy.optimize import linear_sum_assignment

import jflex
from jflex import identify as idf

# the thesis' robots: a sibling module of the experiments (their folder is no package in a checkout)
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _machining_robot import MachiningRobot  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT = ROOT / "configs" / "seed003_prediction.yaml"
TABLE = {"staubli_tx200": "4.5", "kuka_kr90": "4.6"}


# --- the config's schema (jflex.experiment_cli validates the YAML against it) ------------------------
class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


Positive = Annotated[float, Field(gt=0)]


class Weights(_Strict):
    frequency: Annotated[float, Field(ge=0)] = 1.0
    damping: Annotated[float, Field(ge=0)] = 1.0


class Wrist(_Strict):
    q5_deg: Annotated[list[float], Field(min_length=3, max_length=3)] = Field(description="Table 4.1 wrist angle per configuration")
    mass_kg: Positive = Field(description="wrist body beyond q5 as a point mass (an assumption)")
    lever_m: Positive = Field(description="its distance beyond the wrist centre along the forearm (an assumption)")


class RobotEntry(_Strict):
    config: str = Field(description="config of one of the thesis' robots (staubli_tx200 or kuka_kr90), relative to configs/")
    extra_modes_configuration1_Hz: list[Positive] = Field([], description="EMA modes of configuration 1 the table leaves out")
    wrist: Wrist | None = None


class PredictionConfig(_Strict):
    robots: Annotated[list[RobotEntry], Field(min_length=1)]
    hold: str = "actuated"
    max_steps: Annotated[int, Field(ge=1)] = 60
    weights: Weights = Field(default_factory=Weights)
    diagnose: bool = Field(True, description="run jflex.gap.diagnose (False: K,C refit only)")
    splits: Annotated[list[Annotated[list[Annotated[int, Field(ge=1, le=3)]], Field(min_length=1, max_length=2)]],
                      Field(min_length=1)] = Field(description="configurations fitted (1-based); the others are predicted")


# --- the case folder the diagnosis reads -------------------------------------------------------------
def _point_mass(m, p):
    x, y, z = p
    return m * np.array([1.0, x, y, z, y * y + z * z, -x * y, x * x + z * z, -x * z, -y * z, x * x + y * y])


def write_case(folder: pathlib.Path, rob, base_model, entry: dict, train, validation) -> np.ndarray:
    """A case folder as experiments/gap_seed003.py writes them, from ``base_model``'s links (the
    per-joint reflected rotor inertias removed), and, with a ``wrist``, joint q5 as a fourth,
    rigid joint carrying a point mass moved out of link 3; configurations ``train`` (0-based)
    train, ``validation`` validate. Returns the postures (P, n_case)."""
    folder.mkdir(parents=True, exist_ok=True)
    spec = jflex.load_yaml(ROOT / "configs" / "seed003" / rob.cfg["robot"])
    P = np.asarray(base_model.robot.inertia).copy()
    P[np.abs(P) < 1e-9] = 0.0
    # link 1 turns about the fixed vertical axis: base parameters fix only its Izz; Ixx = Iyy =
    # Izz / 2 as gap_seed003 assumes (it matters only once a candidate tilts joint 1)
    P[0, 4] = P[0, 6] = 0.5 * P[0, 9]
    q = rob.postures
    notes = "robot of the thesis, links realised from the base parameters with per-joint reflected rotor inertias"
    w = entry.get("wrist")
    if w:
        tool = list(spec["dh"]["tool"])
        a_w = float(tool[1])  # the wrist centre: the tool row of Table 2.2 (alpha 0, a along x3)
        spec["dh"]["rows"].append(tool)
        spec["dh"]["tool"] = [0, 0.0, 0.0, 0]
        spec["joint_names"] = list(spec["joint_names"]) + ["joint5"]
        m, lever = float(w["mass_kg"]), float(w["lever_m"])
        # at q5 = 0 the mass sits where link 3's realisation already has it: M(q) unchanged there
        P = np.vstack([P, _point_mass(m, [lever, 0.0, 0.0])])
        P[2] -= _point_mass(m, [a_w + lever, 0.0, 0.0])
        q = np.column_stack([q, np.radians(w["q5_deg"])])
        notes += f"; joint5 (wrist q5, Table 4.1) with an assumed {m} kg point mass {lever} m beyond the wrist centre"
    spec["notes"] = notes
    (folder / "robot.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    np.savez(folder / "inertia.npz", inertia=P)
    th = rob.thesis
    extra = list(entry.get("extra_modes_configuration1_Hz", []))
    for k in range(3):
        f = np.r_[th["frequency_exp_Hz"][k], extra if k == 0 else []]
        z = np.r_[th["damping_exp_pct"][k] / 100, [np.nan] * len(extra) if k == 0 else []]
        o = np.argsort(f)
        np.savez(folder / f"modes_c{k + 1}.npz", q0=q[k], freq=f[o], zeta=z[o])
    n_j = 3
    case = dict(
        robot="robot.yaml", robot_inertia="inertia.npz", tool_frame="tool",
        nominal_effects=[dict(effect="joint_flexibility", joint=[f"joint{j + 1}" for j in range(n_j)],
                              stiffness=[float(v) for v in rob.K], damping=[float(v) for v in rob.C])],
        datasets=[dict(kind="modal", file=f"modes_c{k + 1}.npz", split="train", name=f"c{k + 1}_train") for k in train]
        + [dict(kind="modal", file=f"modes_c{k + 1}.npz", split="validation", name=f"c{k + 1}") for k in validation],
        noise=dict(modal_frequency_pct=1.0), notes=f"Table {TABLE[rob.name]} (Exp.) of the MASc thesis \"Posture Dependent Dynamics in Robotic Machining\"; {notes}",
    )
    (folder / "case.yaml").write_text(yaml.safe_dump(case, sort_keys=False))
    return q


# --- models ------------------------------------------------------------------------------------------
class Variant:
    """A model to fit: the jflex Model, its postures (P, n), the coordinates held, the parameters
    freed and the config-1 modes that are the table rows (plus extra measured modes)."""

    def __init__(self, label, model, postures, hold, spec, effects_added):
        self.label, self.model, self.postures, self.hold = label, model, postures, hold
        self.spec, self.effects_added = spec, effects_added


def kc_spec(extra: bool):
    fr = [idf.Free("K_N_m_per_rad", lambda m: m.effects[0].stiffness, transform=idf.Log()),
          idf.Free("C_N_m_s_per_rad", lambda m: m.effects[0].damping, transform=idf.Log())]
    if extra:
        fr.append(idf.Free("added_springs_N_m_per_rad", lambda m: m.effects[1].stiffness, transform=idf.Log()))
    return idf.ParameterSpec(fr)


def diagnosed_variant(rob, base_model, diag, hold, q_case):
    """K, C and the rotors of ``base_model`` on the diagnosis' final structure (its augmented
    robot: virtual joints of orthogonal compliance or link bending inserted; its extra springs,
    at the values it fitted, as motor-held flexible joints without rotors). ``q_case`` (P, n)
    the case's postures. Returns (model, postures (P, n_aug), hold, whether the added springs'
    stiffnesses are freed in the refit (uncoupled; a coupled pair keeps the diagnosis' matrix),
    their values, the coupling of coupled pairs)."""
    st = diag.final
    lm = st.lm
    aug, springs, x = lm.aug, list(lm.structure.springs), np.asarray(st.x, float)
    S = len(springs)
    k, c = np.exp(x[:S]), np.exp(x[S:2 * S])
    names = list(aug.joint_names)
    main = [names.index(f"joint{j + 1}") for j in range(3)]
    extra = [i for i, s in enumerate(springs) if not (s.kind == "joint" and s.where < 3)]
    fj = base_model.effects[0]
    fx = [jflex.effects.FlexibleJoints(fj.stiffness, fj.damping, rotor_inertia=fj.rotor_inertia, gear_ratio=fj.gear_ratio,
                                       joints=main, coupling=True)]
    added, free_added = [], False
    coupling = np.asarray(lm.coupling(x)) if lm.pairs else np.zeros(0)
    if extra:
        idx = [int(lm.coord[i]) for i in extra]
        Kx = np.diag(k[extra])
        for (a, b), r in zip(lm.pairs, coupling):  # a coupled pair: [[k_a, r sqrt(k_a k_b)], [.., k_b]]
            ia, ib = extra.index(a), extra.index(b)
            Kx[ia, ib] = Kx[ib, ia] = r * np.sqrt(k[a] * k[b])
        free_added = not np.any(Kx - np.diag(np.diag(Kx)))
        fx.append(jflex.effects.FlexibleJoints(np.diag(Kx) if free_added else Kx, c[extra], rotor_inertia=np.zeros(len(extra)),
                                               gear_ratio=np.ones(len(extra)), joints=idx, coupling=False))
        added = [dict(spring=f"{springs[i].kind}@{names[int(lm.coord[i])]}", stiffness_N_m_per_rad=float(k[i]),
                      damping_N_m_s_per_rad=float(c[i]),
                      law=type(springs[i].law).candidate or "viscous") for i in extra]  # the diagnosis' law name
    if rob.cfg.get("gravity_compensator", True):
        fx.append(jflex.effects.FourierGravityCompensator(rob.psi[18:21], joint=main[1]))
    springy = set(main) | {int(lm.coord[i]) for i in extra}
    rigid = [names[i] for i in range(aug.nq) if i not in springy]  # e.g. a wrist joint left rigid
    hold_all = ["theta_*"] + rigid if hold == "actuated" else [hold] + rigid
    q = np.zeros((len(q_case), aug.nq))
    q[:, np.asarray(lm.model_index)] = q_case  # virtual joints at rest
    return jflex.Model(aug, fx), q, hold_all, free_added, added, coupling.tolist()


# --- fitting and prediction ------------------------------------------------------------------------
def table(rob, extra):
    """Exp. rows per configuration (3, m): the table's three rows, then configuration 1's extra
    modes (NaN elsewhere)."""
    th = rob.thesis
    ne = len(extra)
    f = np.concatenate([th["frequency_exp_Hz"], np.full((3, ne), np.nan)], axis=1)
    z = np.concatenate([th["damping_exp_pct"] / 100, np.full((3, ne), np.nan)], axis=1)
    f[0, 3:] = extra
    return f, z


def rows_of(rob, v: Variant, f_rows1):
    """Model-mode index per configuration and table row (3, m): configuration 1's rows matched by
    frequency (the table sorts them so), the others by shape (MachiningRobot.row_order)."""
    f1 = np.asarray(jflex.modal_analysis(v.model, v.postures[0], hold=v.hold).frequency)
    m = len(f_rows1)
    if len(f1) < m:  # a model without a mode for the extra rows: they are dropped by the caller
        raise ValueError("fewer model modes than rows")
    cost = np.abs(f1[None, :] - f_rows1[:, None]) / f_rows1[:, None]
    r, cidx = linear_sum_assignment(cost)
    rows1 = np.empty(m, int)
    rows1[r] = cidx
    order, macs, modes = rob.row_order(v.model, v.hold, rows1=rows1, postures=v.postures)
    return order, macs, modes


def fit_split(rob, v: Variant, train, f_tab, z_tab, cfg):
    w = cfg.get("weights", {})
    model = v.model
    m = f_tab.shape[1]
    res = None
    for _ in range(2):  # pair, fit, re-pair; fit again only if the pairing moved
        order, _, _ = rows_of(rob, Variant(v.label, model, v.postures, v.hold, v.spec, v.effects_added), f_tab[0])
        data = idf.ModalData(v.postures[train], f_tab[train], z_tab[train], mode_index=order[train], hold=v.hold,
                             weights=(w.get("frequency", 1.0), w.get("damping", 1.0), 0.0), name=v.label)
        res = idf.fit(model, v.spec, data, max_steps=int(cfg.get("max_steps", 60)), progress=False)
        model = res.model
        after, macs, modes = rows_of(rob, Variant(v.label, model, v.postures, v.hold, v.spec, v.effects_added), f_tab[0])
        if np.array_equal(after[train], order[train]):
            break
    f = np.take_along_axis(np.asarray(modes.frequency), after, axis=1)[:, :3]
    z = np.take_along_axis(np.asarray(modes.damping_ratio), after, axis=1)[:, :3]
    f_all = np.asarray(modes.frequency)
    return res, f, z, after, macs, f_all, np.asarray(modes.damping_ratio)


def nearest_pairing_errors(f_model_all, f_exp):
    """|f - f_exp| / f_exp [%] per row, rows paired with model modes by nearest frequency
    (one-to-one assignment, the diagnosis' rule)."""
    cost = np.abs(f_model_all[None, :] - f_exp[:, None]) / f_exp[:, None]
    r, c = linear_sum_assignment(cost)
    out = np.empty(len(f_exp))
    out[r] = 100 * cost[r, c]
    return out


def thesis_rows(rob):
    th = rob.thesis
    ef = 100 * np.abs(th["frequency_model_Hz"] - th["frequency_exp_Hz"]) / th["frequency_exp_Hz"]
    ez = np.abs(th["damping_model_pct"] - th["damping_exp_pct"])
    return ef, ez


def evaluate(rob, v: Variant, extra, train, cfg):
    """Fit ``v`` on configurations ``train`` (0-based), predict all three; errors per row."""
    n_modes = len(np.asarray(jflex.modal_analysis(v.model, v.postures[0], hold=v.hold).frequency))
    ex = extra if n_modes >= 3 + len(extra) else []
    f_tab, z_tab = table(rob, ex)
    test = [c for c in range(3) if c not in train]
    res, f, z, order, macs, f_all, _ = fit_split(rob, v, train, f_tab, z_tab, cfg)
    fe, ze = rob.thesis["frequency_exp_Hz"], rob.thesis["damping_exp_pct"]
    ef, ez = 100 * np.abs(f - fe) / fe, np.abs(100 * z - ze)
    ef_near = np.array([nearest_pairing_errors(f_all[k], fe[k]) for k in range(3)])
    d = res.to_dict()
    return dict(values=d["values"], std=d["std"], singular_values=d["singular_values"], weak_directions=d.get("weak_directions"),
                fit_result=d.get("result"), steps=d.get("steps"), effects_added=v.effects_added, extra_rows_fitted_Hz=ex,
                frequency_Hz=f, damping_pct=100 * z, mode_index=order, mac_to_configuration1=macs, all_model_frequencies_Hz=f_all,
                frequency_error_pct=ef, damping_error_pct_points=ez,
                heldout_mean_frequency_error_pct=float(ef[test].mean()),
                heldout_mean_damping_error_pct_points=float(ez[test].mean()),
                heldout_mean_frequency_error_nearest_pairing_pct=float(ef_near[test].mean()))


def run(cfg: dict, run_dir: pathlib.Path) -> dict:
    hold = cfg.get("hold", "actuated")
    results = {"hold": hold, "row_pairing": "by shape likeness to configuration 1 (MachiningRobot.row_order, "
               "jflex.linear.pair_modes: 1 - MAC + 0.1 x relative frequency distance, Hungarian); configuration 1's rows by frequency",
               "averaging": "held-out: mean over every table row (3 modes) of every configuration not fitted; "
                            "all rows: over the 9 rows of the table",
               "protocol": "per split, the diagnosis trains and validates on the fitted configurations only (it never sees "
                           "the predicted ones); both models are fitted on the fitted configurations",
               "robots": {}}
    md = ["# Predicting held-out EMA configurations (Staubli TX200, Kuka KR90)", "",
          "Held-out mean |frequency error| [%] and mean |damping error| [points] over the table rows of the "
          "configurations not fitted; the thesis' own errors are its Model column against its Exp. column on the same rows.", "",
          "| robot | fitted | predicted | effects diagnosed | thesis f [%] | K,C refit f [%] | K,C + diagnosed f [%] | thesis zeta [pt] | "
          "K,C refit zeta [pt] | K,C + diagnosed zeta [pt] | source |",
          "|---|---|---|---|---|---|---|---|---|---|---|"]
    fig, axes = plt.subplots(1, len(cfg["robots"]), figsize=(6.5 * len(cfg["robots"]), 4.6), squeeze=False)
    for ax, entry in zip(axes[0], cfg["robots"]):
        path = ROOT / "configs" / entry["config"]
        rob = MachiningRobot.from_config(path)
        base, how = rob.configured_model()
        tab = TABLE[rob.name]
        ef_th, ez_th = thesis_rows(rob)
        extra = list(entry.get("extra_modes_configuration1_Hz", []))
        out = {"rotor_model": how, "thesis_table": f"the thesis \"Posture Dependent Dynamics in Robotic Machining\", Table {tab}",
               "thesis_reported_mean_frequency_error_pct": {
                   "value": float(rob.thesis["mean_frequency_error_pct"]),
                   "source": f"section 4.7 of the MASc thesis \"Posture Dependent Dynamics in Robotic Machining\", text under Table {tab}",
                   "averaging": "all nine rows" if rob.name == "staubli_tx200" else "configurations 2-3 (six rows)"},
               "thesis_rows": [dict(configuration=k + 1, row=i + 1, source=f"the thesis \"Posture Dependent Dynamics in Robotic Machining\", Table {tab}, configuration {k + 1}, row {i + 1}",
                                    frequency_exp_Hz=float(rob.thesis["frequency_exp_Hz"][k, i]),
                                    frequency_model_Hz=float(rob.thesis["frequency_model_Hz"][k, i]),
                                    frequency_error_pct=float(ef_th[k, i]), damping_exp_pct=float(rob.thesis["damping_exp_pct"][k, i]),
                                    damping_model_pct=float(rob.thesis["damping_model_pct"][k, i]),
                                    damping_error_pct_points=float(ez_th[k, i])) for k in range(3) for i in range(3)],
               "thesis_mean_frequency_error_all_rows_pct": float(ef_th.mean()),
               "thesis_mean_frequency_error_configurations_2_3_pct": float(ef_th[1:].mean()),
               "wrist_assumption": entry.get("wrist"), "splits": []}
        for split in cfg["splits"]:
            train = [c - 1 for c in split]
            test = [c for c in range(3) if c not in train]
            sp = dict(fitted_configurations=split, predicted_configurations=[c + 1 for c in test],
                      thesis_heldout_mean_frequency_error_pct=float(ef_th[test].mean()),
                      thesis_heldout_mean_damping_error_pct_points=float(ez_th[test].mean()),
                      thesis_source=f"the thesis \"Posture Dependent Dynamics in Robotic Machining\", Table {tab}, configurations {', '.join(str(c + 1) for c in test)}, rows 1-3 (Model vs Exp.)",
                      models={})
            variants = [Variant("K,C refit", base, rob.postures, hold, kc_spec(False), [])]
            if cfg.get("diagnose", True):
                tag = "".join(map(str, split))
                folder = run_dir / "cases" / f"{rob.name}_fit{tag}"
                q_case = write_case(folder, rob, base, entry, train, train)
                diag = jflex.gap.diagnose(folder, progress=lambda s_, n=rob.name: print(f"{n} diagnose: {s_}", flush=True))
                try:
                    jflex.gap.write_report(diag, run_dir / f"diagnosis_{rob.name}_fit{tag}")
                except Exception as err:  # the report's HTML page is not ours to fix; keep the numbers
                    print(f"{rob.name}: write_report failed ({type(err).__name__}: {err}); diagnosis.json only", flush=True)
                    jflex.write_results(run_dir / f"diagnosis_{rob.name}_fit{tag}", diag.result)
                r = diag.result
                model_d, q_d, hold_d, free_added, added, coupling = diagnosed_variant(rob, base, diag, hold, q_case)
                sp["diagnosis"] = dict(case=str(folder), selected=[(e["effect"], e["joint"] or e.get("link"), e["shrink"]) for e in r["selected"]],
                                       ranking=[(e["effect"], e["joint"] or e.get("link"), e["shrink"]) for e in r["ranking"][:5]],
                                       verdict=r.get("verdict"), gap_before_pct=r["gap_before"], gap_after_pct=r["gap_after"],
                                       added_springs_at_diagnosis=added, pair_coupling=coupling,
                                       added_springs_refitted=free_added, rigid_held=hold_d[1:])
                variants.append(Variant("K,C + diagnosed", model_d, q_d, hold_d, kc_spec(free_added), added))
            for v in variants:
                sp["models"][v.label] = evaluate(rob, v, extra, train, cfg)
                e = sp["models"][v.label]
                print(f"{rob.name} [{v.label}] fit {split}: held-out f {e['heldout_mean_frequency_error_pct']:.2f} % "
                      f"(nearest {e['heldout_mean_frequency_error_nearest_pairing_pct']:.2f} %), "
                      f"zeta {e['heldout_mean_damping_error_pct_points']:.2f} pt; thesis {sp['thesis_heldout_mean_frequency_error_pct']:.2f} %",
                      flush=True)
            out["splits"].append(sp)
            s0, s1 = sp["models"]["K,C refit"], sp["models"].get("K,C + diagnosed")
            eff = ", ".join(f"{a}@{b}" for a, b, _ in sp["diagnosis"]["selected"]) if "diagnosis" in sp else "-"

            def cell(key, m=s1):
                return f"{m[key]:.2f}" if m else "-"

            md.append(f"| {rob.name} | {', '.join(map(str, split))} | {', '.join(map(str, sp['predicted_configurations']))} | "
                      f"{eff or 'none'} | {sp['thesis_heldout_mean_frequency_error_pct']:.2f} | {s0['heldout_mean_frequency_error_pct']:.2f} | "
                      f"{cell('heldout_mean_frequency_error_pct')} | {sp['thesis_heldout_mean_damping_error_pct_points']:.2f} | "
                      f"{s0['heldout_mean_damping_error_pct_points']:.2f} | {cell('heldout_mean_damping_error_pct_points')} | "
                      f"{sp['thesis_source']} |")
        results["robots"][rob.name] = out
        labels = [", ".join(map(str, sp["fitted_configurations"])) for sp in out["splits"]]
        xs = np.arange(len(labels))
        ax.bar(xs - 0.27, [sp["thesis_heldout_mean_frequency_error_pct"] for sp in out["splits"]], 0.27,
               label=f"thesis (Table {tab} Model vs Exp.)", color="0.6")
        for j, lab in enumerate(("K,C refit", "K,C + diagnosed")):
            if all(lab in sp["models"] for sp in out["splits"]):
                ax.bar(xs + 0.27 * j, [sp["models"][lab]["heldout_mean_frequency_error_pct"] for sp in out["splits"]], 0.27,
                       label=f"jflex: {lab}")
        ax.set_xticks(xs, [f"fit {lab}" for lab in labels])
        ax.set_ylabel("held-out mean |f error| [%]")
        ax.set_title(f"{rob.name}: configurations not fitted")
        ax.legend(fontsize=7)
    fig.text(0.5, 0.0, "Bars: mean |f_pred - f_exp| / f_exp over the table rows of the configurations not fitted; thesis: its Model "
             "column against its Exp. column on the same rows (Tables 4.5, 4.6 of the MASc thesis \"Posture Dependent Dynamics in Robotic Machining\"); it fitted configuration 1, so where "
             "a split predicts configuration 1 its bar is in-sample.", ha="center", va="top", fontsize=8, wrap=True)
    fig.tight_layout()
    fig.savefig(run_dir / "prediction.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    md += ["", "Thesis figures as reported: Staubli 5.47 % over all nine rows of Table 4.5 (held-out rows, configurations 2-3: "
           "7.68 %); Kuka 12.8 % over configurations 2-3 of Table 4.6. The thesis fitted configuration 1 only: where a split "
           "predicts configuration 1, the thesis column is its in-sample error there, not a prediction. "
           "Per-mode values, fitted parameters, singular values: results.json."]
    (run_dir / "prediction.md").write_text("\n".join(md) + "\n")
    return results


def quick_figures(res) -> dict:
    """The key figures of ``--quick`` (the KR90 fitted on configuration 1), loosely: the K, C refit
    reproduces Table 4.6's Exp. rows of configuration 1 (10.0, 11.0, 23.7 Hz) within 1 %, the
    diagnosis names the orthogonal compliance of joint 1, and the model with it predicts
    configurations 2-3 better than the K, C refit."""
    sp = res["robots"]["kuka_kr90"]["splits"][0]
    f = sp["models"]["K,C refit"]["frequency_Hz"][0]
    out = {f"K,C refit, configuration 1 row {k + 1} [Hz] (Table 4.6: {ref})": (f[k], ref * 0.99, ref * 1.01)
           for k, ref in enumerate((10.0, 11.0, 23.7))}
    out["orthogonal_compliance selected first (1 = yes)"] = (
        float([e[0] for e in sp["diagnosis"]["selected"]][:1] == ["orthogonal_compliance"]), 1, 1)
    kc = sp["models"]["K,C refit"]["heldout_mean_frequency_error_pct"]
    out["diagnosed / K,C refit held-out mean frequency error"] = (
        sp["models"]["K,C + diagnosed"]["heldout_mean_frequency_error_pct"] / kc, 0.0, 1.0)
    return out


def main(argv=None):
    return jflex.experiment_cli("seed003_prediction", DEFAULT, run, argv, description=__doc__, schema=PredictionConfig,
                                quick=(DEFAULT.with_name("seed003_prediction_quick.yaml"), quick_figures))


if __name__ == "__main__":
    main(sys.argv[1:])
