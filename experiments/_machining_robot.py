"""Rigid dynamics of two machining robots in terms of their identified base parameters, as the
MASc thesis "Posture Dependent Dynamics in Robotic Machining" gives them (its Appendix B; "the thesis" below).
The model the posture_modal, identify_seed003, seed003_prediction and gap_seed003 experiments share
(a sibling module of theirs, not part of the jflex library: it is loaded by path, the experiment
folder being no package when run from a checkout).

The thesis gives M(q) and G(q) of the Staubli TX200 and Kuka KR90 (3 positioning joints) as a
regressor ``Phi(q, qdd)`` times 15 base parameters. ``realisation_matrix`` finds link inertial
parameters (jflex order) that reproduce each column, so the identified values can drive a
:class:`jflex.Model` (the realisation is not unique and need not be physical per link).
"""

from __future__ import annotations

import pathlib

import numpy as np

from jflex._dynamics import regressor
from jflex._sweep import sweep

G0 = -9.81  # Appendix B writes gravity torques with g = -9.81 (z up): -g cos(q2) psi_3 > 0


def appendix_b_columns(q, qdd, a1, a2):
    """Columns 1..15 of the thesis regressor Phi at zero velocity (link part: rotor terms 16-18
    and compensator/friction columns are handled by the effects). Shape (3, 15).

    Phi(3,13) and Phi(3,15) read ``qd_1`` in the OCR text; symmetry of M(q) with Phi(1,13),
    Phi(1,15) says ``qdd_1``, which is what is used here.
    """
    q1, q2, q3 = q
    d1, d2, d3 = qdd
    s, c = np.sin, np.cos
    P = np.zeros((3, 15))
    P[0, 0] = d1
    P[0, 2] = 2 * a1 * d1 * c(q2)
    P[0, 3] = -2 * a1 * d1 * s(q2)
    P[0, 4] = d1 / 2 - d1 * c(2 * q2) / 2
    P[0, 5] = -d2 * s(q2)
    P[0, 6] = -d1 * s(2 * q2)
    P[0, 7] = -d2 * c(q2)
    P[0, 9] = d1 * (a2 * c(q3) + a2 * c(2 * q2 + q3) + 2 * a1 * c(q2 + q3))
    P[0, 10] = -d1 * (a2 * s(q3) + a2 * s(2 * q2 + q3) + 2 * a1 * s(q2 + q3))
    P[0, 11] = d1 / 2 - d1 * c(2 * q2 + 2 * q3) / 2
    P[0, 12] = -(d2 + d3) * s(q2 + q3)
    P[0, 13] = -d1 * s(2 * q2 + 2 * q3)
    P[0, 14] = -(d2 + d3) * c(q2 + q3)
    P[1, 1] = d2
    P[1, 2] = -G0 * c(q2)
    P[1, 3] = G0 * s(q2)
    P[1, 5] = -d1 * s(q2)
    P[1, 7] = -d1 * c(q2)
    P[1, 8] = d2 + d3
    P[1, 9] = 2 * a2 * d2 * c(q3) - G0 * c(q2 + q3) + a2 * d3 * c(q3)
    P[1, 10] = G0 * s(q2 + q3) - 2 * a2 * d2 * s(q3) - a2 * d3 * s(q3)
    P[1, 12] = -d1 * s(q2 + q3)
    P[1, 14] = -d1 * c(q2 + q3)
    P[2, 8] = d2 + d3
    P[2, 9] = a2 * d2 * c(q3) - G0 * c(q2 + q3)
    P[2, 10] = G0 * s(q2 + q3) - a2 * d2 * s(q3)
    P[2, 12] = -d1 * s(q2 + q3)
    P[2, 14] = -d1 * c(q2 + q3)
    return P


def realisation_matrix(robot, a1, a2, n_samples=60, seed=0):
    """R (30, 15): link inertial parameters (jflex order) realising each base parameter, i.e.
    ``regressor(q, 0, qdd) @ R = Phi_1..15(q, qdd)`` (least squares over random samples; the
    realisation is not unique and need not be physical, only its base combinations matter)."""
    rng = np.random.default_rng(seed)
    Q = rng.uniform(-np.pi, np.pi, (n_samples, 3))
    D = rng.normal(size=(n_samples, 3))
    Y = sweep(lambda q, d: regressor(robot, q, 0 * q, d), Q, D, progress=False).reshape(-1, 30)
    P = np.concatenate([appendix_b_columns(q, d, a1, a2) for q, d in zip(Q, D)])
    R, *_ = np.linalg.lstsq(Y, P, rcond=None)
    rel = np.linalg.norm(Y @ R - P, axis=0) / np.maximum(np.linalg.norm(P, axis=0), 1e-300)
    return R, rel


class MachiningRobot:
    """One robot of the thesis (Staubli TX200 or Kuka KR90, 3 positioning joints) as the thesis models
    it: DH kinematics, rigid dynamics from the 27 identified base parameters (Tables 3.3/3.6),
    flexible joints with the stiffness and damping of Tables 4.3/4.4, rotors, the gravity
    compensator of joint 2, and the EMA postures (Tables 4.1/4.2) with the thesis' tables.

    Build it from a config (``configs/seed003/*.yaml``) with :meth:`from_config`; get a
    :class:`jflex.Model` for given gear ratios with :meth:`model`. The gear ratios are not in the
    thesis. Two ways to close that gap, both fitted to the thesis' Model frequencies at one
    posture: :meth:`fit_common_ratio` (one ratio for all joints with the thesis' rule
    ``I_m,i = (r_i / r_3) I_m,3``), or :meth:`fit_reflected_inertia` (the reflected rotor inertia
    ``r_i^2 I_m,i`` of joints 1 and 2 each free; :meth:`reflected_model`), which is what the
    held-motor modes actually see: a common ratio leaves the Kuka 5.6 % off the thesis' Model
    column, per-joint values < 1 %.
    """

    def __init__(self, cfg: dict, cfg_dir):
        from jflex._config import load_robot
        from jflex._errors import ConfigError

        cfg_dir = pathlib.Path(cfg_dir)
        self.cfg = cfg
        self.name = cfg["name"]
        self.robot0 = load_robot(str((cfg_dir / cfg["robot"]).resolve()))
        dh = np.asarray(self.robot0.placement_p)
        self.a1, self.a2 = float(dh[1, 0]), float(dh[2, 0])
        psi = np.asarray(cfg["base_parameters"], dtype=float)
        if psi.shape != (27,):
            raise ConfigError(f"{self.name}.base_parameters: expected 27 numbers (Table 3.3/3.6), got shape {psi.shape}")
        self.psi = psi
        self.K = np.asarray(cfg["stiffness"], dtype=float)
        self.C = np.asarray(cfg["damping"], dtype=float)
        # link parameters realising each base parameter (only their base combinations matter)
        self.R, self.realisation_error = realisation_matrix(self.robot0, self.a1, self.a2)
        self.postures = np.radians(np.asarray(cfg["postures_deg"], dtype=float))
        self.thesis = {k: np.asarray(v, dtype=float) if isinstance(v, list) else v for k, v in cfg["thesis"].items()}

    @classmethod
    def from_config(cls, path) -> "MachiningRobot":
        from jflex._runs import load_yaml

        path = pathlib.Path(path)
        return cls(load_yaml(path), path.parent)

    def model(self, r, K=None, C=None, *, reflected_inertia=None):
        """The flexible-joint :class:`jflex.Model` for gear ratios ``r`` (3,); ``K``, ``C``
        override the tables' joint stiffness and damping (any of them may be traced).

        ``reflected_inertia`` (3,) [kg m^2], if given, sets each joint's ``r_i^2 I_m,i`` directly
        (rotor ``I_m,i = J_i / r_i^2``) instead of the thesis' rule ``I_m,i = (r_i / r_3) I_m,3``.
        """
        from jflex import effects
        from jflex._model import Model

        r1, r2, r3 = r[0], r[1], r[2]
        if reflected_inertia is None:
            Im3 = self.psi[15]
            Im = [r1 / r3 * Im3, r2 / r3 * Im3, Im3 + 0.0 * r3]  # thesis: I_m,i = (r_i / r_3) I_m,3
            J1, J2 = r1**2 * Im[0], r2**2 * Im[1]
        else:
            J = reflected_inertia
            Im = [J[0] / r1**2, J[1] / r2**2, J[2] / r3**2]
            J1, J2 = J[0], J[1]
        # psi_1 and psi_2 hold the reflected rotor inertias r_i^2 I_m,i, which the rotors of the
        # flexible-joint effect carry themselves: remove them from the links' share (joint 3's
        # rotor is not in the 15 link columns; with the motors held it does not enter the modes)
        e0, e1 = np.eye(15)[0], np.eye(15)[1]
        p_link = self.psi[:15] - J1 * e0 - J2 * e1
        robot = self.robot0.replace(inertia=(self.R @ p_link).reshape(3, 10))
        K = self.K if K is None else K
        C = self.C if C is None else C
        fx = [effects.FlexibleJoints(K, C, rotor_inertia=Im, gear_ratio=[r1, r2, r3], coupling=True)]
        if self.cfg.get("gravity_compensator", True):
            fx.append(effects.FourierGravityCompensator(self.psi[18:21], joint=1))
        return Model(robot, fx)

    def reflected_ratios(self, reflected_inertia):
        """Gear ratios (3,) that go with reflected inertias ``J`` (3,): ``r_i = sqrt(J_i / I_m)``
        with ``I_m`` the one rotor inertia the thesis identifies (psi_16, I_m,3) for every rotor.
        With the motors held only ``J_1``, ``J_2`` shape the modes; the ratios only size the
        rotors' small spin coupling."""
        return np.sqrt(np.asarray(reflected_inertia, dtype=float) / abs(self.psi[15]))

    def reflected_model(self, reflected_inertia, K=None, C=None):
        """:meth:`model` with per-joint reflected rotor inertias ``J`` (3,) [kg m^2] (the gear
        ratios from :meth:`reflected_ratios`; ``J`` may be traced, the ratios then are too)."""
        import jax.numpy as jnp

        J = jnp.asarray(reflected_inertia, dtype=float)
        r = jnp.sqrt(J / abs(self.psi[15]))
        return self.model(r, K, C, reflected_inertia=J)

    def configured_model(self, K=None, C=None):
        """The model the config's ``gear_ratios`` entry describes, and a sentence saying how:
        ``mode: per_joint_reflected`` uses its ``reflected_inertia_kg_m2``; ``fit_common`` fits one
        ratio (:meth:`fit_common_ratio`); ``given`` takes ``values``."""
        from jflex._errors import ConfigError

        gr = self.cfg.get("gear_ratios", {"mode": "fit_common"})
        mode = gr.get("mode", "fit_common")
        if mode == "per_joint_reflected":
            J = np.asarray(gr["reflected_inertia_kg_m2"], dtype=float)
            how = f"per-joint reflected rotor inertias {np.round(J, 1).tolist()} kg m^2 ({gr.get('provenance', 'config')})"
            return self.reflected_model(J, K, C), how
        if mode == "fit_common":
            posture = int(gr.get("posture", 0))
            r, err = self.fit_common_ratio(posture, gr.get("bounds", [20, 600]))
            how = f"one common ratio {r:.1f} fitted to the thesis Model frequencies of configuration {posture + 1} (rms {100 * err:.3f} %)"
            return self.model(np.full(3, r), K, C), how
        if mode == "given":
            return self.model(np.asarray(gr["values"], dtype=float), K, C), "gear ratios given in the config"
        raise ConfigError(f"{self.name}.gear_ratios.mode: expected per_joint_reflected, fit_common or given, got {mode!r}")

    def fit_common_ratio(self, posture: int = 0, bounds=(20.0, 600.0), hold="actuated", n_grid: int = 601):
        """One gear ratio for all joints reproducing the thesis' Model frequencies at ``posture``:
        the best of a log-spaced grid (one compiled sweep). Returns (r, rms relative error).

        The rotors take ``r^2 I_m`` out of the identified inertias psi_1 and psi_2 (:meth:`model`),
        so past some ratio the links are left a mass matrix that is not positive definite: no
        physical model, and a ratio of the grid only where the links keep one. A
        :class:`jflex.ParameterError` if no ratio within ``bounds`` does."""
        import jax.numpy as jnp

        from jflex._errors import ParameterError
        from jflex.linear import linearization, modes
        from jflex.linear._common import mass_ok

        target = np.sort(self.thesis["frequency_model_Hz"][posture])
        q = self.postures[posture]
        grid = np.exp(np.linspace(np.log(bounds[0]), np.log(bounds[1]), n_grid))

        def frequencies(r):
            # modes() rather than modal_analysis(), which refuses (inside the sweep: raises for
            # the whole grid) the ratios whose links are left without a positive definite M
            _, lin = linearization(self.model(r * jnp.ones(3)), q, hold)
            return modes(lin.M, lin.C, lin.K).frequency, mass_ok(lin.M)

        f, ok = sweep(frequencies, grid, chunk_size=n_grid, progress=False)
        err = np.sqrt(np.mean(((np.sort(f, axis=1) - target) / target) ** 2, axis=1))
        err[~(np.asarray(ok) & np.isfinite(err))] = np.inf
        if not np.isfinite(err).any():
            raise ParameterError(
                f"{self.name}.gear_ratios.bounds: no common ratio within {list(bounds)} leaves the links a positive "
                f"definite mass matrix at configuration {posture + 1} (the rotors' r^2 I_m exceeds the identified inertia)")
        k = int(np.argmin(err))
        return float(grid[k]), float(err[k])

    def fit_reflected_inertia(self, posture: int = 0, hold="actuated", start=(300.0, 300.0)):
        """Reflected rotor inertias ``J_1``, ``J_2`` [kg m^2] reproducing the thesis' Model
        frequencies at ``posture`` (least squares on log J, relative errors of the sorted
        frequencies); ``J_3`` (not observable with the motors held) set to ``J_2 (r_3 = r_2)``.
        Returns (J (3,), relative errors (3,) at the posture)."""
        import jax
        import scipy.optimize as so

        from jflex.linear import modal_analysis

        target = np.sort(self.thesis["frequency_model_Hz"][posture])
        q = self.postures[posture]
        freq = jax.jit(lambda J: modal_analysis(self.reflected_model(J), q, hold=hold).frequency)

        def res(x):
            J = np.exp(np.r_[x, x[1]])
            return (np.sort(np.asarray(freq(J))) - target) / target

        sol = so.least_squares(res, np.log(np.asarray(start, dtype=float)), x_scale=1.0, xtol=1e-12, ftol=1e-12)
        J = np.exp(np.r_[sol.x, sol.x[1]])
        return J, res(sol.x)

    def row_order(self, model, hold="actuated", frame=None, rows1=(0, 1, 2), postures=None):
        """The model modes in the thesis tables' row order at each EMA posture: configuration 1
        by frequency, the others paired with configuration 1's shapes
        (:func:`jflex.linear.pair_modes`, MAC first, frequency as tie-break), as Tables 4.5/4.6
        label rows by mode shape. ``rows1``: the model modes (by frequency) of configuration 1
        that are the table's rows (a model with more modes than rows, e.g. an added bearing
        tilt); ``postures`` (P, n) default the EMA postures (robot joints, then any extra).
        Returns (index (P, len(rows1)) int, MAC with configuration 1 (P, len(rows1)), the
        :class:`jflex.linear.Modes` of all postures, batched)."""
        import jax

        from jflex.linear import modal_analysis, pair_modes

        postures = self.postures if postures is None else np.asarray(postures)
        modes = jax.vmap(lambda q: modal_analysis(model, q, hold=hold, frame=frame))(postures)
        f, S = np.asarray(modes.frequency), np.asarray(modes.shape)
        r1 = np.asarray(rows1, dtype=int)
        pairs = [pair_modes(S[0][:, r1], S[k], f[0][r1], f[k]) for k in range(len(postures))]
        return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs]), modes
