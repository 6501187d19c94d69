"""The gap diagnosis' nominal model and noise floor on cases made by independent code (Pinocchio,
NumPy, SciPy; benchmarks/gap/independent):

* with 10 % CAD mass errors and exact derivatives, the nominal inertial refit is the optimum of its
  own penalised, bounded least-squares problem, solved again from Pinocchio's joint-torque
  regressor with ``scipy.optimize.lsq_linear``, and every parameter it leaves at a bound is named;
* on a periodic log of a 12-bit encoder the floor holds the processing error that repeats with
  the period (the quantisation's, through the filter, the derivatives and the model), so the gap
  it leaves is not alarmed; with exact angles the processing term is about nil.
"""

import pathlib
import sys

import numpy as np
import pinocchio as pin
import pytest
import yaml
from scipy.optimize import lsq_linear
from scipy.signal import butter, sosfiltfilt

import jflex
from jflex.gap._inertia import PARAM_NAMES, link_moves
from jflex.gap.judge._noise import noise_floor
from jflex.gap.judge._periodic import periodic_noise
from jflex.gap._problem import Problem

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import cases as C  # noqa: E402
from independent import robots as R  # noqa: E402
from independent import signals as S  # noqa: E402
from independent import torque as TQ  # noqa: E402

NOISE = 0.01  # white torque noise, x each channel's noise-free torque std


def _write(folder, model, tool, sets):
    """A case folder: ``model`` as the nominal URDF, ``sets`` [(name, split, arrays)] as NPZ."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.urdf").write_text(R.urdf_text(model, tool, "arm3"))
    ds = []
    for name, split, arrays in sets:
        np.savez(folder / f"{name}.npz", **arrays)
        ds.append(dict(kind="torque", file=f"{name}.npz", split=split))
    (folder / "case.yaml").write_text(yaml.safe_dump(dict(robot="robot.urdf", datasets=ds), sort_keys=False))
    return folder


# --- 1. the nominal refit against an independent bounded least-squares solve -----------------------
def _cad_null_case(folder, com_m, seed=0, mass=(1.10, 0.90, 1.10)):
    """arm3 with CAD masses 10 % off (+, -, +; rotational inertia scaled alike) and each link's
    centre of mass shifted by ``com_m[i]`` [m] in a random direction; exact q, qd, qdd of Fourier
    trajectories (200 Hz, 3 s), torque = Pinocchio's RNEA on the true robot + 1 % white noise.
    Two training sets, one validation set. Returns ``(folder, cad model)``."""
    rng = np.random.default_rng(seed)
    true, tool, home = R.true_model("arm3")
    cad = true.copy()
    for i in range(1, true.njoints):
        I = true.inertias[i]
        s = mass[i - 1]
        d = rng.normal(size=3)
        d *= com_m[i - 1] / np.linalg.norm(d)
        cad.inertias[i] = pin.Inertia(I.mass * s, I.lever + d, I.inertia * s)
    t = np.arange(600) / 200.0
    amp = C._amp(true, home, 0.7)
    sets = []
    for k in range(3):
        tr = S.Fourier(rng, home + rng.uniform(-0.15, 0.15, true.nq) * (amp > 0.3), amp, f0=1.0 / 3.0)
        q, qd, qdd = tr(t), tr(t, 1), tr(t, 2)
        tau = TQ.rnea_batch(true, q, qd, qdd)
        tau = tau + NOISE * tau.std(axis=0) * rng.standard_normal(tau.shape)
        sets.append((f"traj{k}", "train" if k < 2 else "validation", dict(t=t, q=q, qd=qd, qdd=qdd, tau=tau)))
    return _write(folder, cad, tool, sets), cad


def _at_bound(x, lo, hi):
    return (np.abs(x - lo) < 1e-6 * np.abs(lo)) | (np.abs(x - hi) < 1e-6 * np.abs(hi))


@pytest.mark.parametrize("com_m", [(0.01, 0.01, 0.01), (0.01, 0.01, 0.035)], ids=["within", "beyond"])
def test_nominal_refit_is_the_bounded_least_squares_optimum(tmp_path, com_m):
    # 'within': every true parameter inside the CAD tolerance box (10 % of mass, 2 cm of centre of
    # mass); 'beyond': the last link's centre of mass 3.5 cm off CAD, past the box: the refit must
    # stop at the bound and name it
    folder, cad = _cad_null_case(tmp_path / "case", com_m)
    case = jflex.gap.load_case(folder)
    pb = Problem(case)
    tfit = pb.nominal_state().tfit
    prior = pb.inertia
    assert prior is not None and tfit.delta is not None, "the inertial refit was dropped (training BIC)"

    # the reference problem, built from the data and Pinocchio; from jflex only its inputs: the
    # prior's penalty (its weight and the noise level it is weighed against), bounds and scales
    data = cad.createData()
    pi_cad = np.concatenate([cad.inertias[i].toDynamicParameters() for i in range(1, cad.njoints)])
    np.testing.assert_allclose(prior.pi0, pi_cad, rtol=1e-10, atol=1e-12)  # same parameters, same order
    A, y = [], []
    for s in pb.ttrain:
        z = np.load(folder / f"{s.name}.npz")
        Y = np.stack([pin.computeJointTorqueRegressor(cad, data, a, b, c).copy()
                      for a, b, c in zip(z["q"], z["qd"], z["qdd"])])
        sc = z["tau"].std(axis=0)
        np.testing.assert_allclose(s.scale, sc, rtol=1e-12)  # rows normalised by the set's torque spread
        A.append((Y / sc[None, :, None]).reshape(-1, Y.shape[2]))
        y.append(((z["tau"] - Y @ pi_cad) / sc).ravel())
    A, y = np.concatenate(A), np.concatenate(y)
    pen = prior.penalty()
    lo, hi = prior.bounds()

    def J(x):
        return float(np.sum((A @ x - y) ** 2) + np.sum(pen * x**2))

    ref = lsq_linear(np.vstack([A, np.diag(np.sqrt(pen))]), np.concatenate([y, np.zeros(pen.size)]),
                     bounds=(lo, hi), method="bvls", tol=1e-14)
    assert ref.success
    got = tfit.delta
    assert np.all(got >= lo) and np.all(got <= hi)
    assert J(got) <= J(ref.x) * (1 + 1e-9), (J(got), J(ref.x))
    # the penalty makes the objective strictly convex: at the bounded optimum x*, J(x) - J(x*) >=
    # (x - x*)' H (x - x*) for every feasible x, so the cost bounds the parameters' distance in the
    # metric of H, identifiable combinations tightest; in units of the prior's scale besides
    dx = got - ref.x
    H = A.T @ A + np.diag(pen)
    assert dx @ H @ dx <= 1e-9 * J(ref.x)
    np.testing.assert_allclose(got / prior.scale, ref.x / prior.scale, atol=1e-5)
    # jflex's own cost is the unpenalised weighted residual of the same rows
    np.testing.assert_allclose(tfit.cost, np.sum((A @ got - y) ** 2), rtol=1e-8)

    # the bounds it stopped at are the optimum's, and each is named
    hit = _at_bound(got, lo, hi)
    np.testing.assert_array_equal(hit, _at_bound(ref.x, lo, hi))
    moves = {m["link"]: m for m in link_moves(pb.robot, prior.pi0, got, prior)}
    names = list(pb.robot.link_names)
    for k in np.flatnonzero(hit):
        m = moves[names[k // 10]]
        assert m["at_tolerance_bound"]
        assert any(b.startswith(PARAM_NAMES[k % 10] + " +") or b.startswith(PARAM_NAMES[k % 10] + " -")
                   for b in m["bound_parameters"]), (PARAM_NAMES[k % 10], m["bound_parameters"])
    assert sum(len(m["bound_parameters"]) for m in moves.values()) == int(hit.sum())
    rms = np.sqrt(np.mean((A @ got - y) ** 2))
    if com_m[2] > 0.02:
        assert hit.any(), "a centre of mass 3.5 cm off CAD was absorbed within the 2 cm box"
    else:
        # inside the box, the refit leaves the training noise (1 % white), not CAD error
        assert rms < 1.05 * NOISE, rms


# --- 2. a periodic log's floor and the repeating processing error ----------------------------------
PERIOD = 1.0  # [s], a whole number of samples at 1 kHz: the quantisation error repeats exactly
BITS = 12  # encoder counts per turn 2^12: the processing error it leaves stands above MIN_GAP
TORQUE_NOISE = 0.001  # white torque noise, x each channel's torque std


def _periodic_case(folder, quantised: bool, seed=0):
    """arm3 (CAD = truth), two Fourier excitations of period PERIOD repeated 4 times at 1 kHz;
    angles only (quantised to 2 pi / 2^BITS, or exact), torque = Pinocchio's RNEA along the exact
    motion + small white noise. Returns ``(folder, exact validation angles)``."""
    rng = np.random.default_rng(seed)
    true, tool, home = R.true_model("arm3")
    t = np.arange(int(round(4 * PERIOD * 1000))) / 1000.0
    amp = C._amp(true, home, 0.7)
    sets = []
    for k in range(2):
        tr = S.Fourier(rng, home, amp, f0=1.0 / PERIOD)
        q = tr(t)
        tau = TQ.rnea_batch(true, q, tr(t, 1), tr(t, 2))
        tau = tau + TORQUE_NOISE * tau.std(axis=0) * rng.standard_normal(tau.shape)
        qm = S.quantise(q, 2 * np.pi / 2**BITS) if quantised else q
        sets.append((f"per{k}", "train" if k == 0 else "validation", dict(t=t, q=qm, tau=tau)))
    return _write(folder, true, tool, sets), q


def _quantisation_error(q, cutoff, trim):
    """(n,) RMS [N m] of what the encoder's rounding alone changes in the processed model torque
    (SciPy: the zero-phase 4th-order Butterworth at ``cutoff`` on the angles, central differences,
    Pinocchio's RNEA, the same low-pass again), ``trim`` samples off each end."""
    true = R.true_model("arm3")[0]
    h = 1e-3
    sos = butter(4, cutoff / (0.5 / h), output="sos")

    def lp(x):
        return sosfiltfilt(sos, x, axis=0, padtype="odd", padlen=36)

    def model(qa):
        qf = lp(qa)
        qd = np.gradient(qf, h, axis=0)
        return lp(TQ.rnea_batch(true, qf, qd, np.gradient(qd, h, axis=0)))

    e = (model(S.quantise(q, 2 * np.pi / 2**BITS)) - model(q))[trim:-trim]
    return np.sqrt(np.mean(e**2, axis=0))


@pytest.fixture(scope="module")
def periodic(tmp_path_factory):
    """The 12-bit periodic case diagnosed, its exact-angle twin's floor details and the
    quantisation's own processing error."""
    base = tmp_path_factory.mktemp("periodic")
    folder, q_exact = _periodic_case(base / "quantised", True)
    result = jflex.gap.diagnose(folder).result
    twin = jflex.gap.load_case(_periodic_case(base / "exact", False)[0])
    pb = Problem(twin)
    ev = pb.evaluate(pb.nominal_state())
    det = noise_floor(pb, ev, twin).details
    case = jflex.gap.load_case(folder)
    s = Problem(case).tval[0]
    cutoff = float(s.processing["cutoff_hz"])
    trim = int(round(float(s.processing["trimmed_s"]) * 1000))
    return dict(result=result, twin=det["per1"], twin_gap=ev["per1"]["nrmse"], set=s,
                quant=_quantisation_error(q_exact, cutoff, trim))


def test_periodic_floor_holds_the_repeating_processing_error(periodic):
    r, s = periodic["result"], periodic["set"]
    d = r["noise_floor_details"]["per1"]
    assert "scatter between periods" in d["method"] and "with the processing error" in d["method"]
    assert not d["failed"]
    assert all(v > 0 for v in d["processing_nm"])
    floor = d["floor"]
    nominal_gap = r["gap_before"]  # the one validation set's
    # the nominal model (CAD = truth) leaves the processing error, well beyond MIN_GAP: without the
    # processing term the scatter between periods alone is far below it (an alarm on a null case)
    assert nominal_gap > 0.3
    sig, dof, info = periodic_noise(s.t, s.q, s.tau, np.ones(s.scale.size, bool))
    scatter = 100 * np.sqrt(np.sum(sig**2) / np.sum(s.scale**2))
    assert scatter < 0.2 * nominal_gap, (scatter, nominal_gap)
    assert floor >= 0.95 * nominal_gap, (floor, nominal_gap)
    assert r["verdict"] == "within_noise" and not r["selected"] and not r["significant"]
    # the gap is what the quantisation alone leaves after the processing (independent: SciPy +
    # Pinocchio), plus the small torque noise
    quant = 100 * np.sqrt(np.sum(periodic["quant"] ** 2) / np.sum(s.scale**2))
    assert 0.8 * quant < nominal_gap < 1.25 * quant + 0.05, (quant, nominal_gap)


def test_exact_angles_leave_about_no_processing_term(periodic):
    q = np.asarray(periodic["result"]["noise_floor_details"]["per1"]["processing_nm"])
    e = np.asarray(periodic["twin"]["processing_nm"])
    assert np.all(e <= 0.1 * q), (e, q)
    # their gap (0.11 %: the filter's own error on the nonlinear model, the model's torque filtered
    # twice against the measured once, repeats with the period and is in no floor) stays under MIN_GAP
    assert periodic["twin_gap"] < 0.2


def test_processing_term_is_the_quantisation_error(periodic):
    d = periodic["result"]["noise_floor_details"]["per1"]
    ratio = np.asarray(d["processing_nm"]) / periodic["quant"]
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio
    # (the Gaussian redraws that propagate it overstate a staircase's error somewhat: 1.6 x here;
    # with the second difference's one-count MAD read as noise the floor was 2.6 x the gap)
    assert d["floor"] < 2.0 * periodic["result"]["gap_before"]


def test_a_cad_further_off_than_its_tolerance_is_named_not_alarmed(tmp_path):
    """The second link's CAD mass 25 % light and its centre of mass 6 cm off (the box: 10 % and 2 cm)
    and nothing else: the refit stops at its bound and leaves a gap beyond the noise; no effect of
    the library is the cause. The diagnosis says the CAD is further off than its tolerance (naming
    that link) and raises no alarm when no candidate took the gap first."""
    folder, cad = _cad_null_case(tmp_path / "case", (0.01, 0.06, 0.01), seed=1, mass=(1.05, 0.75, 0.95))
    # (a payload fits the same torques as a heavier link and is tried first: with candidates
    # allowed it is named here; none allowed, the gap is the nominal model's own)
    r = jflex.gap.diagnose(folder, max_effects=0).result
    assert r["significant"] and not r["selected"]
    assert r["verdict"] == "within_noise", (r["verdict"], r["stop_reason"])
    far = r["cad_beyond_tolerance"]
    assert far is not None and far["gap"] < r["gap_before"]
    links = {x["link"]: x["parameters"] for x in far["links"]}
    second = jflex.load_urdf(folder / "robot.urdf").link_names[1]
    assert second in links, links
    assert "further off than its tolerance" in r["stop_reason"]
