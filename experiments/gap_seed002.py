"""Gap diagnosis on a high-speed multi-link press: perfect joints against stiff joints.

The press is that of the paper "Elastic dynamic research of high-speed multi-link precision press considering structural stiffness of rotation joints".

The nominal model is the press of ``configs/press.yaml`` with perfect pins. The data are the
elastic BDC deviation of the main slider against crank speed: (i) synthetic records of a richer
"real" press (each pin's bar moduli scaled by its own factor, bushes softer in tension than the
paper's ratio, repeated noisy records), trained on low speeds and validated on higher ones, and
(ii) the press paper's measured 0.13 mm growth from 200 to 600 spm, set beside the model rungs.

Candidates, each one scale factor fitted on the training speeds by least squares (a log grid,
then golden-section refinement; see :func:`fit` for why not gradients): ``joint_flexibility`` (bar-element pins with the paper's moduli times a
scale), ``link_flexibility`` (every beam's E times a scale), ``damping`` (the modal damping ratio
times a scale), ``payload`` (the main slider's lumped mass times a scale). They are ranked and
forward-selected on the validation gap by the rules of :func:`jflex.gap.forward_select`.

Usage: ``python experiments/gap_seed002.py [configs/gap_seed002.yaml] [--out DIR]`` or
``jflex run gap_seed002 [CONFIG] [--out DIR]``. Writes ``results.json``, ``diagnosis.json`` and
plots into the run folder. See docs/press.md.
"""

import pathlib
import sys
import time
from typing import Annotated, Any, Literal

import equinox as eqx
import jax.numpy as jnp
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

import jflex
from jflex import fem
from jflex.gap import (MIN_GAP, SIGNIFICANCE, forward_select, gap_summary, ic_delta, is_significant, rank_entries,
                       repeats_factor, step_record)

NAME = "gap_seed002"
ROOT = pathlib.Path(__file__).resolve().parent.parent
DEFAULT = ROOT / "configs" / "gap_seed002.yaml"
EFFECTS = ("joint_flexibility", "link_flexibility", "damping", "payload")
# where each effect sits, in the ranking's "joint" field (None: not at a joint)
PLACE = {"joint_flexibility": "all pins", "link_flexibility": None, "damping": None, "payload": None}
# log-grid ranges of the scale factors: wide enough that the truth of a plausible press is inside
RANGE = {"joint_flexibility": (0.1, 4.0), "link_flexibility": (0.1, 2.0), "damping": (0.1, 6.0), "payload": (0.5, 8.0)}
UNIT = {"joint_flexibility": "x paper's bar moduli", "link_flexibility": "x beam E", "damping": "x zeta",
        "payload": "x main-slider lumped mass"}
JOINT_NAMES = tuple(j[0] for j in fem.PRESS_JOINTS)


# --- config --------------------------------------------------------------------------------------
def _speeds(v, field):
    try:
        s = np.asarray(v, float).ravel()
    except (TypeError, ValueError):
        raise jflex.ConfigError(f"{field}: expected a list of speeds in spm, got {v!r}") from None
    if s.size == 0 or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise jflex.ConfigError(f"{field}: expected positive speeds in spm, got {v!r}")
    return s


def _positive(d, key, field, integer=False, minimum=0.0):
    if key not in d:
        raise jflex.ConfigError(f"{field}.{key}: missing")
    v = d[key]
    if integer and (not isinstance(v, int) or isinstance(v, bool) or v < minimum):
        raise jflex.ConfigError(f"{field}.{key}: expected an integer >= {minimum:g}, got {v!r}")
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise jflex.ConfigError(f"{field}.{key}: expected a number, got {v!r}") from None
    if not np.isfinite(x) or x <= minimum and not integer:
        raise jflex.ConfigError(f"{field}.{key}: expected a number > {minimum:g}, got {v!r}")
    return v if integer else x


def parse(cfg: dict) -> dict:
    """Check the config; every bad field is a :class:`jflex.ConfigError` naming it."""
    pc = cfg.get("press_config", "press.yaml")
    path = pathlib.Path(pc)
    if not path.is_absolute():
        path = ROOT / "configs" / path
    pcfg = jflex.load_yaml(path)
    ov = cfg.get("press_overrides", {}) or {}
    if not isinstance(ov, dict):
        raise jflex.ConfigError("press_overrides: expected a mapping of press fields")
    pcfg["press"] = {**pcfg.get("press", {}), **ov}
    g = cfg.get("gap")
    if not isinstance(g, dict):
        raise jflex.ConfigError("gap: missing section (see configs/gap_seed002.yaml)")
    train = _speeds(g.get("train_speeds_spm"), "gap.train_speeds_spm")
    bands = g.get("validation_bands_spm")
    if not isinstance(bands, list) or not bands:
        raise jflex.ConfigError("gap.validation_bands_spm: expected a list of speed lists, e.g. [[450, 500], [550, 600]]")
    bands = [_speeds(b, f"gap.validation_bands_spm[{k}]") for k, b in enumerate(bands)]
    allv = np.concatenate(bands)
    if len(set(allv.tolist())) != allv.size or set(allv.tolist()) & set(train.tolist()):
        raise jflex.ConfigError("gap.validation_bands_spm: validation speeds must be distinct and not among the training speeds")
    truth = g.get("truth")
    if not isinstance(truth, dict) or not isinstance(truth.get("joint_factors"), dict):
        raise jflex.ConfigError(f"gap.truth.joint_factors: expected a mapping pin -> factor for {', '.join(JOINT_NAMES)}")
    jf = truth["joint_factors"]
    if set(jf) != set(JOINT_NAMES):
        raise jflex.ConfigError(f"gap.truth.joint_factors: expected exactly the pins {', '.join(JOINT_NAMES)}, got {sorted(jf)}")
    factors = np.array([_positive(jf, j, "gap.truth.joint_factors") for j in JOINT_NAMES])
    tension = _positive(truth, "tension_factor", "gap.truth") if "tension_factor" in truth else 1.0
    noise = g.get("noise")
    if not isinstance(noise, dict):
        raise jflex.ConfigError("gap.noise: expected {sigma_mm, repeats, seed}")
    cands = g.get("candidates", list(EFFECTS))
    if not isinstance(cands, list) or not cands or any(c not in EFFECTS for c in cands):
        raise jflex.ConfigError(f"gap.candidates: expected a non-empty list of {', '.join(EFFECTS)}, got {cands!r}")
    fit = g.get("fit", {}) or {}
    return dict(
        press=pcfg, train=train, bands=bands,
        poses=_positive(g, "poses_per_rev", "gap", integer=True, minimum=16) if "poses_per_rev" in g else 120,
        n_modes=_positive(g, "n_modes", "gap", integer=True, minimum=1) if "n_modes" in g else 30,
        zeta=_positive(g, "zeta", "gap") if "zeta" in g else 0.05,
        factors=factors, tension=tension, perfect_truth=bool(truth.get("perfect_joints", False)),
        sigma=_positive(noise, "sigma_mm", "gap.noise") * 1e-3,
        repeats=_positive(noise, "repeats", "gap.noise", integer=True, minimum=2),
        seed=int(noise.get("seed", 0)),
        candidates=tuple(cands),
        max_effects=_positive(g, "max_effects", "gap", integer=True, minimum=1) if "max_effects" in g else 2,
        grid=_positive(fit, "grid_points", "gap.fit", integer=True, minimum=3) if "grid_points" in fit else 9,
        steps=_positive(fit, "golden_steps", "gap.fit", integer=True, minimum=0) if "golden_steps" in fit else 8,
        paper=g.get("paper", {}) or {},
    )


# --- the press as a function of the effects' scale factors ---------------------------------------
class PressModel:
    """BDC deviation of the press at a fixed set of speeds, for any set of effects added."""

    def __init__(self, p: dict):
        self.geo = fem.press_from_config(p["press"])
        self.pfe = {v: fem.press_fe(self.geo, v) for v in ("perfect", "joints")}
        self.speeds = np.sort(np.concatenate([p["train"], *p["bands"]]))
        self.n_poses = p["poses"]
        self.n_modes = p["n_modes"]
        self.zeta = p["zeta"]
        self.bar_joint = np.array(self.pfe["joints"].bar_joint)
        self.evals = 0

    def deviation(self, effects: tuple, theta, bar_factors=None, tension=1.0):
        """Elastic BDC deviation of the main slider (m, negative = down) at ``self.speeds``.

        ``theta``: log scale factor of each effect in ``effects``. ``bar_factors``: per-pin factors
        on the paper's bar moduli (the truth), with ``tension`` on the tension modulus.
        """
        self.evals += 1
        th = dict(zip(effects, [theta[k] for k in range(len(effects))]))
        geo = self.geo
        joints = bar_factors is not None or "joint_flexibility" in th
        pfe = self.pfe["joints" if joints else "perfect"]
        if bar_factors is not None:
            # _poses picks E_t / E_c / E_n per bar with jnp.where, so per-bar arrays broadcast there:
            # one modulus triple per pin without a second press model
            f = jnp.asarray(bar_factors)[self.bar_joint]
            geo = eqx.tree_at(lambda g: (g.E_t, g.E_c, g.E_n), geo, (geo.E_t * f * tension, geo.E_c * f, geo.E_n * f))
        elif "joint_flexibility" in th:
            s = jnp.exp(th["joint_flexibility"])
            geo = eqx.tree_at(lambda g: (g.E_t, g.E_c, g.E_n), geo, (geo.E_t * s, geo.E_c * s, geo.E_n * s))
        if "link_flexibility" in th:
            pfe = eqx.tree_at(lambda p: p.model.beam_E, pfe, pfe.model.beam_E * jnp.exp(th["link_flexibility"]))
        if "payload" in th:
            # the last lumped mass is the main slider's (press_fe adds pins, then m1, then m2)
            lm = pfe.model.lumped_m
            pfe = eqx.tree_at(lambda p: p.model.lumped_m, pfe, lm.at[-1].multiply(jnp.exp(th["payload"])))
        # ModalDamping checks its ratio with float(), which a traced value cannot pass
        damping = eqx.tree_at(lambda d: d.zeta, fem.ModalDamping(self.zeta), self.zeta * jnp.exp(th.get("damping", 0.0)))
        pp = fem.press_poses(geo, pfe, self.n_poses)
        md = fem.pose_modes(pp.M, pp.K, min(self.n_modes, pfe.model.n_dof))
        out = []
        for spm in self.speeds:
            w = fem.spm_to_rad_s(spm)
            r = fem.ked_periodic(pp.M, pp.K, w**2 * pp.G, 2 * np.pi / w, damping, pose_modes_=md, static_correction=True)
            out.append(r.U[0, pfe.slider_dof])
        return jnp.stack(out)


# --- data ----------------------------------------------------------------------------------------
class Data:
    """Repeated BDC records (m) at every speed, the training mask and the validation bands."""

    def __init__(self, speeds, truth, p):
        rng = np.random.default_rng(p["seed"])
        self.speeds = speeds
        self.truth = np.asarray(truth)
        self.repeats = self.truth[None] + p["sigma"] * rng.standard_normal((p["repeats"], speeds.size))
        self.mean = self.repeats.mean(axis=0)
        # the data are the mean of R records: its noise is one record's over sqrt(R)
        self.sigma_mean = self.repeats.std(axis=0, ddof=1) / repeats_factor(self.repeats, self.mean)
        self.train = np.isin(speeds, p["train"])
        self.bands = {f"{b.min():.0f}-{b.max():.0f} spm": np.isin(speeds, b) for b in p["bands"]}
        # one pooled noise level for the weights: per-speed spreads from 4 records are themselves noisy
        self.w = 1.0 / np.sqrt(np.mean(self.sigma_mean[self.train] ** 2))

    def evaluate(self, model_dev) -> dict:
        """Per validation band: NRMSE [%] = |model - data| / |data| over the band's speeds, per speed too."""
        m = np.asarray(model_dev)
        out = {}
        for name, idx in self.bands.items():
            err = m[idx] - self.mean[idx]
            ref = np.sqrt(np.sum(self.mean[idx] ** 2))
            out[name] = dict(nrmse=float(np.linalg.norm(err) / ref * 100), neff=float(idx.sum()),
                             channels={f"{s:.0f} spm": float(abs(e) / abs(d) * 100)
                                       for s, e, d in zip(self.speeds[idx], err, self.mean[idx])})
        return out

    def floor(self) -> dict:
        return {name: float(np.sqrt(np.sum(self.sigma_mean[idx] ** 2)) / np.sqrt(np.sum(self.mean[idx] ** 2)) * 100)
                for name, idx in self.bands.items()}


# --- fits ----------------------------------------------------------------------------------------
def fit(model: PressModel, data: Data, effects: tuple, theta0, grid_points: int, steps: int):
    """Least squares of the training BDC deviations over the log scale factors of ``effects``.

    A robust derivative-free search: the newest effect (last) is scanned over its log grid with
    the others held (the deviation against speed is not monotone in a pin or link scale once a
    harmonic of the crank nears a natural frequency, so a local method from one start can end in
    a side minimum), then golden-section refined inside the best grid cell; earlier effects are
    then refined one at a time around their values. (The FEM and KED are JAX and forward-mode
    derivatives through them match finite differences to 1e-6, but compiling the differentiated
    periodic solve stalled XLA's CPU runtime on the shared test machine, so they are not used.)
    Returns ``(theta, deviation at all speeds, grid)``, grid = [(theta_new, deviation)].
    """
    tr = data.train
    seen = {}

    def cost(th):
        key = tuple(np.round(th, 12))
        if key not in seen:
            dev = np.asarray(model.deviation(effects, jnp.asarray(th)))
            r = (dev[tr] - data.mean[tr]) * data.w
            seen[key] = (float(r @ r), dev)
        return seen[key][0]

    th = np.r_[np.asarray(theta0, float)[: len(effects) - 1], 0.0]
    lo, hi = np.log(RANGE[effects[-1]])
    gs = np.linspace(lo, hi, grid_points)
    costs = []
    for g in gs:
        th[-1] = g
        costs.append(cost(th))
    i = int(np.argmin(costs))
    th[-1] = gs[i]
    grid = [(float(g), seen[tuple(np.round(np.r_[th[:-1], g], 12))][1]) for g in gs]
    half = gs[1] - gs[0]
    order = [len(effects) - 1] + list(range(len(effects) - 1))
    for k in order:
        a, b = th[k] - half, th[k] + half
        if k != len(effects) - 1:
            a, b = th[k] - 0.3, th[k] + 0.3
        _golden(lambda x, k=k, t=th.copy(): cost(np.r_[t[:k], x, t[k + 1:]]), a, b, steps)
        th = np.array(min(seen.items(), key=lambda kv: kv[1][0])[0])
    best = min(seen.items(), key=lambda kv: kv[1][0])
    return np.array(best[0]), best[1][1], grid


def _golden(f, a, b, n):
    """Golden-section search of f on [a, b] with n further evaluations (the caller keeps the best)."""
    r = (np.sqrt(5) - 1) / 2
    c, d = b - r * (b - a), a + r * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(n):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - r * (b - a)
            fc = f(c)
        else:
            a, c, fc = c, d, fd
            d = a + r * (b - a)
            fd = f(d)


# --- diagnosis -----------------------------------------------------------------------------------
def where(data: Data, ev: dict, floor: dict) -> list:
    """The nominal gap per validation band and per speed, largest first."""
    out = []
    for name, r in ev.items():
        idx = data.bands[name]
        out.append(dict(dataset=name, channel="bdc_deviation", band_spm=[float(data.speeds[idx].min()), float(data.speeds[idx].max())],
                        nrmse=r["nrmse"], floor=floor[name], significant=bool(r["nrmse"] > SIGNIFICANCE * floor[name] + MIN_GAP)))
        for ch, v in r["channels"].items():
            out.append(dict(dataset=name, channel=ch, band_spm=[float(ch.split()[0])] * 2, nrmse=v, floor=floor[name]))
    out.sort(key=lambda w: -w["nrmse"])
    return out


def _entry(effects, ev, ev0, floor, score, theta):
    gap, _, exc = gap_summary(ev, floor)
    g0, _, exc0 = gap_summary(ev0, floor)
    shrink = 100.0 * (1 - exc / exc0) if exc0 > 0 else 0.0
    c = effects[-1]
    return dict(effect=c, joint=PLACE[c], score=float(score), gap_after=gap, shrink=float(np.clip(shrink, 0, 100)),
                shrink_raw=float(100 * (1 - gap / g0)) if g0 > 0 else 0.0,
                per_dataset={k: v["nrmse"] for k, v in ev.items()},
                fitted={e: {"scale": float(np.exp(t)), "unit": UNIT[e]} for e, t in zip(effects, theta)})


def diagnose(model: PressModel, data: Data, p: dict, say=print):
    """Nominal gap, candidates ranked by held-out shrink, forward selection (rules of jflex.gap)."""
    t0 = time.perf_counter()
    curves = {"nominal": np.asarray(model.deviation((), jnp.zeros(0)))}
    ev0 = data.evaluate(curves["nominal"])
    floor = data.floor()
    gap0, fl, exc0 = gap_summary(ev0, floor)
    significant = is_significant(ev0, floor)
    say(f"nominal (perfect joints): validation gap {gap0:.2f} % (noise floor {fl:.2f} %), significant: {significant}")
    ranking, fitted, grids = [], {}, {}
    # with nothing significant to explain, no candidate is refitted (each refit costs ~20 KED solves)
    for c in p["candidates"] if significant else ():
        th, dev, grid = fit(model, data, (c,), np.zeros(1), p["grid"], p["steps"])
        ev = data.evaluate(dev)
        score = -ic_delta(ev, ev0, 1)
        fitted[c] = ((c,), th, dev, ev)
        grids[c] = grid
        ranking.append(_entry((c,), ev, ev0, floor, score, th))
        say(f"  {c}: scale {np.exp(th[0]):.3f}, gap {ranking[-1]['gap_after']:.2f} %, shrink {ranking[-1]['shrink']:.0f} %")
    order = rank_entries(ranking)
    ranking = [ranking[i] for i in order]
    # forward selection: the loop of jflex.gap.diagnose; a state is (effects, theta, deviation)

    def refit(state, c):
        effects = state[0] + (c,)
        th, dev, _ = fit(model, data, effects, np.r_[state[1], 0.0], p["grid"], p["steps"])
        return (effects, th, dev), data.evaluate(dev)

    def on_select(st):
        say(f"selected {st.cand}: gap {gap_summary(st.ev, floor)[0]:.2f} %")

    sel = forward_select(((), np.zeros(0), curves["nominal"]), ev0, floor, p["candidates"], refit, n_params=lambda c: 1,
                         max_effects=p["max_effects"], first={c: (v[:3], v[3]) for c, v in fitted.items()},
                         on_select=on_select)
    selected = []
    for st in sel.steps:
        selected.append(_entry(st.state[0], st.ev, ev0, floor, st.score, st.state[1]))
        selected[-1]["step_shrink"] = st.step_shrink
    steps = [step_record(None, ev0, floor)] + [step_record(st.cand, st.ev, floor) for st in sel.steps]
    state, ev_cur = sel.state, sel.ev
    ambiguous = []
    if len(ranking) >= 2 and significant:
        a, b = ranking[0], ranking[1]
        if abs(a["shrink"] - b["shrink"]) < 5.0:
            ambiguous.append(dict(effects=[a["effect"], b["effect"]], shrink=[a["shrink"], b["shrink"]]))
    gap_after, _, exc_after = gap_summary(ev_cur, floor)
    result = dict(
        case="multi-link press: BDC deviation vs speed (synthetic truth)", gap_before=gap0, gap_after=gap_after, noise_floor=fl,
        noise_floor_per_dataset=floor, excess_before=exc0, excess_after=exc_after,
        shrink=float(np.clip(100 * (1 - exc_after / exc0), 0, 100)) if exc0 > 0 else 0.0,
        significant=bool(significant), remaining_significant=bool(is_significant(ev_cur, floor)),
        where=where(data, ev0, floor), ranking=ranking, selected=selected, ambiguous=ambiguous, steps=steps,
        parameters={e: {"scale": float(np.exp(t)), "unit": UNIT[e]} for e, t in zip(state[0], state[1])},
        model_evaluations=model.evals, seconds=time.perf_counter() - t0,
        units={"gap": "NRMSE % of the BDC deviation over a band", "noise_floor": "NRMSE %",
               "shrink": "% of the excess over noise closed"},
    )
    curves.update({c: v[2] for c, v in fitted.items()})
    curves["final"] = np.asarray(state[2])
    return result, curves, grids


# --- the run -------------------------------------------------------------------------------------
def _growth(dev, speeds, lo=200.0, hi=600.0):
    """|deviation(hi) - deviation(lo)| in mm, or None where a speed is not in the set."""
    if lo not in speeds or hi not in speeds:
        return None
    i, j = int(np.flatnonzero(speeds == lo)[0]), int(np.flatnonzero(speeds == hi)[0])
    return float(abs(dev[j] - dev[i]) * 1e3)


def _scale_for_growth(grid, speeds, target_mm):
    """The joint scale whose 200->600 spm growth is ``target_mm``, interpolated on the fit's grid (log scale)."""
    pts = sorted((g, _growth(d, speeds)) for g, d in grid)
    if any(v is None for _, v in pts):
        return None
    for (g0, v0), (g1, v1) in zip(pts[:-1], pts[1:]):
        if (v0 - target_mm) * (v1 - target_mm) <= 0 and v0 != v1:
            return float(np.exp(g0 + (target_mm - v0) * (g1 - g0) / (v1 - v0)))
    return None


def run(cfg: dict, out: pathlib.Path) -> dict:
    p = parse(cfg)
    t0 = time.time()
    say = lambda s: print(f"[{time.time() - t0:6.1f}s] {s}", flush=True)
    model = PressModel(p)
    S = model.speeds
    if p["perfect_truth"]:
        truth = np.asarray(model.deviation((), jnp.zeros(0)))  # the null case: nothing to find
    else:
        truth = np.asarray(model.deviation((), jnp.zeros(0), bar_factors=p["factors"], tension=p["tension"]))
    data = Data(S, truth, p)
    say(f"{model.pfe['perfect'].model.n_dof} / {model.pfe['joints'].model.n_dof} DOF (perfect / joints), {p['poses']} poses, "
        f"speeds {S.min():.0f}-{S.max():.0f} spm")
    result, curves, grids = diagnose(model, data, p, say)
    paper_joints = np.asarray(model.deviation(("joint_flexibility",), jnp.zeros(1)))
    curves["paper_joints"] = paper_joints

    paper = {"bdc_growth_perfect_mm": 0.027, "bdc_growth_joints_mm": 0.118, "bdc_growth_measured_mm": 0.13,
             "measured_resolution_mm": 0.005, **p["paper"]}
    meas, res_mm = float(paper["bdc_growth_measured_mm"]), float(paper["measured_resolution_mm"])
    rungs = {"nominal (perfect joints)": curves["nominal"], "joints at the paper's moduli": paper_joints,
             **{f"fitted {c}": curves[c] for c in p["candidates"] if c in curves}, "selected model": curves["final"],
             "synthetic truth": truth}
    growth = {k: _growth(v, S) for k, v in rungs.items()}
    growth["synthetic data (mean of records)"] = _growth(data.mean, S)
    # (ii) the seed's one measured figure: a gap on one number, its floor the last printed digit
    seed_gap = {k: (abs(g - meas) / meas * 100 if g is not None else None) for k, g in growth.items()}
    f = p["factors"]
    load_path = [JOINT_NAMES.index(j) for j in ("AL", "AR", "QL", "QR", "ML", "MR")]
    jfit = next((r["fitted"]["joint_flexibility"]["scale"] for r in result["ranking"] if r["effect"] == "joint_flexibility"), None)
    truth_ref = {
        "joint_factors": dict(zip(JOINT_NAMES, f.tolist())), "tension_factor": p["tension"],
        "geometric_mean_all_pins": float(np.exp(np.mean(np.log(f)))),
        "geometric_mean_load_path_pins_A_Q_M": float(np.exp(np.mean(np.log(f[load_path])))),
        # bars I/III carry tension or compression, II/IV the mean: the tension factor enters about a quarter
        "geometric_mean_all_pins_with_tension_share": float(np.exp(np.mean(np.log(f)) + 0.25 * np.log(p["tension"]))),
    }
    if jfit is not None:
        truth_ref["fitted_joint_scale"] = jfit
        truth_ref["fitted_over_load_path_mean"] = jfit / truth_ref["geometric_mean_load_path_pins_A_Q_M"]
        truth_ref["fitted_over_all_pins_mean"] = jfit / truth_ref["geometric_mean_all_pins_with_tension_share"]
    res = {
        "speeds_spm": S, "train_speeds_spm": S[data.train], "validation_bands_spm": {k: S[v] for k, v in data.bands.items()},
        "noise": {"sigma_one_record_mm": p["sigma"] * 1e3, "repeats": p["repeats"], "seed": p["seed"]},
        "bdc_deviation_mm": {"data_mean": data.mean * 1e3, "data_sigma_of_mean": data.sigma_mean * 1e3,
                             **{k: np.asarray(v) * 1e3 for k, v in curves.items()}, "truth": truth * 1e3},
        "bdc_growth_200_600_mm": growth,
        "seed002": {**paper, "gap_to_measured_growth_percent": seed_gap,
                    "gap_floor_percent": res_mm / meas * 100,
                    "joint_scale_for_measured_growth": _scale_for_growth(grids.get("joint_flexibility", []), S, meas)},
        "fitted_vs_truth": truth_ref,
        "diagnosis": {k: result[k] for k in ("gap_before", "gap_after", "noise_floor", "significant", "shrink")},
        "selected": [s["effect"] for s in result["selected"]],
        "units": {"bdc_deviation_mm": "mm, elastic vertical deviation of the main slider at BDC (negative = down)",
                  "gap": "NRMSE %", "scales": "dimensionless factors on the nominal values"},
        "plots": ["bdc_vs_speed.png", "gap_waterfall.png"],
    }
    jflex.write_results(out, result, "diagnosis.json")
    _plots(out, S, data, curves, truth, result, p, meas)
    say(f"selected {res['selected']}, gap {result['gap_before']:.2f} -> {result['gap_after']:.2f} % "
        f"(floor {result['noise_floor']:.2f} %); growth 200->600 spm [mm]: "
        + ", ".join(f"{k} {v:.4f}" for k, v in growth.items() if v is not None))
    return res


LABEL = {"joint_flexibility": "joint flexibility (fitted)", "link_flexibility": "link stiffness scale (fitted)",
         "damping": "damping scale (fitted)", "payload": "slider mass scale (fitted)"}


def _plots(out, S, data, curves, truth, result, p, meas):
    fig, ax = plt.subplots(figsize=(7, 4.5))
    tr = data.train
    ax.errorbar(S[tr], data.mean[tr] * 1e3, 2 * data.sigma_mean[tr] * 1e3, fmt="ko", ms=4, label="data, training (mean, 2 sigma)")
    ax.errorbar(S[~tr], data.mean[~tr] * 1e3, 2 * data.sigma_mean[~tr] * 1e3, fmt="o", mfc="w", mec="k", ecolor="k", ms=5,
                label="data, validation")
    ax.plot(S, truth * 1e3, "k:", lw=1, label="synthetic truth (noise-free)")
    ax.plot(S, curves["nominal"] * 1e3, "-", color="0.5", label="nominal: perfect joints")
    ax.plot(S, curves["paper_joints"] * 1e3, "--", color="0.5", label="joints at the paper's moduli")
    for c in (c for c in p["candidates"] if c in curves):
        ax.plot(S, curves[c] * 1e3, "-", lw=1.2, label=LABEL[c])
    if 200.0 in S:
        i = int(np.flatnonzero(S == 200.0)[0])
        ax.plot([600], [data.mean[i] * 1e3 - meas], "r*", ms=11, label=f"measured (press paper): {meas} mm below 200 spm")
    ax.axvspan(S[~tr].min() - 25, S.max() + 25, color="0.92", zorder=0)
    ax.set_xlabel("crank speed (spm)")
    ax.set_ylabel("elastic slider deviation at BDC (mm)")
    ax.set_title(f"gap {result['gap_before']:.1f} % -> {result['gap_after']:.2f} % (floor {result['noise_floor']:.2f} %); "
                 f"selected: {', '.join(s['effect'] for s in result['selected']) or 'nothing'}", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "bdc_vs_speed.png", dpi=120)
    plt.close(fig)

    fig, axs = plt.subplots(1, 2, figsize=(11, 4))
    st = result["steps"]
    labels = ["nominal"] + [f"+ {s['added']}" for s in st[1:]]
    vals = [s["gap"] for s in st]
    axs[0].bar(range(len(vals)), vals, color=["0.5"] + ["tab:blue"] * (len(vals) - 1))
    for k in range(1, len(vals)):
        axs[0].annotate("", (k, vals[k]), (k - 1, vals[k - 1]), arrowprops=dict(arrowstyle="->", color="tab:red"))
    axs[0].axhline(result["noise_floor"], color="k", ls="--", lw=1, label=f"noise floor {result['noise_floor']:.2f} %")
    axs[0].axhline(SIGNIFICANCE * result["noise_floor"] + MIN_GAP, color="k", ls=":", lw=1, label="significance threshold")
    axs[0].set_xticks(range(len(vals)), labels, fontsize=8)
    axs[0].set_yscale("log")
    axs[0].set_ylabel("validation gap (NRMSE %)")
    axs[0].set_title("forward selection")
    axs[0].legend(fontsize=8)
    rk = result["ranking"]
    axs[1].barh(range(len(rk)), [r["gap_after"] for r in rk], color="tab:blue")
    axs[1].axvline(result["gap_before"], color="0.5", lw=1, label="nominal")
    axs[1].axvline(result["noise_floor"], color="k", ls="--", lw=1, label="noise floor")
    axs[1].set_yticks(range(len(rk)), [f"{r['effect']} (shrink {r['shrink']:.0f} %)" for r in rk], fontsize=8)
    axs[1].invert_yaxis()
    axs[1].set_xscale("log")
    axs[1].set_xlabel("validation gap after adding one effect (NRMSE %)")
    axs[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "gap_waterfall.png", dpi=120)
    plt.close(fig)


# --- the config's schema (jflex.experiment_cli validates the YAML against it) ------------------------
class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


Positive = Annotated[float, Field(gt=0)]
Speeds = Annotated[list[Positive], Field(min_length=1)]


def _press_fields():
    # the press section's keys are press_bdc's schema (the experiment folder is not a package)
    name = "jflex_experiment_press_bdc"
    if name not in sys.modules:
        import importlib.util

        spec = importlib.util.spec_from_file_location(name, pathlib.Path(__file__).with_name("press_bdc.py"))
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return list(sys.modules[name].PressConfig.model_fields)


class TruthConfig(_Strict):
    joint_factors: dict[str, Positive] = Field(description="stiffness factor of each pin on the paper's bar moduli")
    tension_factor: Positive = 1.0
    perfect_joints: bool = False

    @field_validator("joint_factors")
    @classmethod
    def _pins(cls, v):
        if set(v) != set(JOINT_NAMES):
            raise ValueError(f"expected exactly the pins {', '.join(JOINT_NAMES)}, got {sorted(v)}")
        return v


class NoiseConfig(_Strict):
    sigma_mm: Positive = Field(description="one record's BDC reading noise [mm]")
    repeats: Annotated[int, Field(ge=2)] = Field(description="records per speed (the data are their mean)")
    seed: int = 0


class FitConfig(_Strict):
    grid_points: Annotated[int, Field(ge=3)] = 9
    golden_steps: Annotated[int, Field(ge=0)] = 8


class GapConfig(_Strict):
    poses_per_rev: Annotated[int, Field(ge=16)] = 120
    n_modes: Annotated[int, Field(ge=1)] = 30
    zeta: Positive = Field(0.05, description="nominal modal damping ratio")
    train_speeds_spm: Speeds
    validation_bands_spm: Annotated[list[Speeds], Field(min_length=1)] = Field(description="one validation set per band")
    truth: TruthConfig
    noise: NoiseConfig
    candidates: Annotated[list[Literal[EFFECTS]], Field(min_length=1)] = list(EFFECTS)
    max_effects: Annotated[int, Field(ge=1)] = 2
    fit: FitConfig = FitConfig()
    paper: dict[str, float] = Field(default_factory=dict, description="the paper's figures, echoed in results")

    @model_validator(mode="after")
    def _distinct(self):
        val = [s for b in self.validation_bands_spm for s in b]
        if len(set(val)) != len(val) or set(val) & set(self.train_speeds_spm):
            raise ValueError("validation speeds must be distinct and not among the training speeds")
        return self


class GapSeed002Config(_Strict):
    press_config: str = Field("press.yaml", description="the press (relative to configs/ unless absolute)")
    press_overrides: dict[str, Any] = Field(default_factory=dict, description="press fields replacing the file's")
    gap: GapConfig

    @field_validator("press_overrides")
    @classmethod
    def _press_keys(cls, v):
        known = _press_fields()
        for k in v:
            if k not in known:
                raise ValueError(f"unknown press field {k!r}; allowed: {known}")
        return v


def quick_figures(res) -> dict:
    """The key figures of ``--quick``, loosely: the joints' flexibility selected and the gap closed
    to within twice the noise floor, its fitted scale near the planted factors' geometric mean
    (0.70), and the selected model's BDC growth within 5 % of the synthetic truth's."""
    d, g = res["diagnosis"], res["bdc_growth_200_600_mm"]
    truth = g["synthetic truth"]
    return {
        "joint_flexibility selected (1 = yes)": (float(res["selected"] == ["joint_flexibility"]), 1, 1),
        "gap after / noise floor": (d["gap_after"] / d["noise_floor"], 0.0, 2.0),
        "fitted joint scale (planted mean 0.70)": (res["fitted_vs_truth"]["fitted_joint_scale"], 0.66, 0.74),
        "BDC growth, selected model [mm]": (g["selected model"], 0.95 * truth, 1.05 * truth),
    }


def main(argv=None):
    jflex.experiment_cli(NAME, DEFAULT, run, sys.argv[1:] if argv is None else argv, description=__doc__.splitlines()[0],
                         schema=GapSeed002Config, quick=(DEFAULT.with_name("gap_seed002_quick.yaml"), quick_figures))


if __name__ == "__main__":
    main()
