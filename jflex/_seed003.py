"""Seed 003's rigid dynamics in terms of its identified base parameters (thesis, Appendix B).

The thesis gives M(q) and G(q) of the Staubli TX200 and Kuka KR90 (3 positioning joints) as a
regressor ``Phi(q, qdd)`` times 15 base parameters. ``realisation_matrix`` finds link inertial
parameters (jflex order) that reproduce each column, so the identified values can drive a
:class:`jflex.Model` (the realisation is not unique and need not be physical per link).
"""

from __future__ import annotations

import pathlib

import numpy as np

from ._dynamics import regressor
from ._sweep import sweep

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


class Seed003Robot:
    """One seed-003 robot (Staubli TX200 or Kuka KR90, 3 positioning joints) as the thesis models
    it: DH kinematics, rigid dynamics from the 27 identified base parameters (Tables 3.3/3.6),
    flexible joints with the stiffness and damping of Tables 4.3/4.4, rotors, the gravity
    compensator of joint 2, and the EMA postures (Tables 4.1/4.2) with the thesis' tables.

    Build it from a config (``configs/seed003/*.yaml``) with :meth:`from_config`; get a
    :class:`jflex.Model` for given gear ratios with :meth:`model`. The gear ratios are not in the
    thesis: :meth:`fit_common_ratio` picks one ratio for all joints that reproduces the thesis'
    Model frequencies at one posture.
    """

    def __init__(self, cfg: dict, cfg_dir):
        from ._config import load_robot
        from ._errors import ConfigError

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
    def from_config(cls, path) -> "Seed003Robot":
        from ._runs import load_yaml

        path = pathlib.Path(path)
        return cls(load_yaml(path), path.parent)

    def model(self, r, K=None, C=None):
        """The flexible-joint :class:`jflex.Model` for gear ratios ``r`` (3,); ``K``, ``C``
        override the tables' joint stiffness and damping (any of them may be traced)."""
        from . import effects
        from ._model import Model

        Im3 = self.psi[15]
        r1, r2, r3 = r[0], r[1], r[2]
        Im = [r1 / r3 * Im3, r2 / r3 * Im3, Im3 + 0.0 * r3]  # thesis: I_m,i = (r_i / r_3) I_m,3
        # psi_1 and psi_2 hold the reflected rotor inertias r_i^2 I_m,i, which the rotors of the
        # flexible-joint effect carry themselves: remove them from the links' share
        e0, e1 = np.eye(15)[0], np.eye(15)[1]
        p_link = self.psi[:15] - r1**2 * Im[0] * e0 - r2**2 * Im[1] * e1
        robot = self.robot0.replace(inertia=(self.R @ p_link).reshape(3, 10))
        K = self.K if K is None else K
        C = self.C if C is None else C
        fx = [effects.FlexibleJoints(K, C, rotor_inertia=Im, gear_ratio=[r1, r2, r3], coupling=True)]
        if self.cfg.get("gravity_compensator", True):
            fx.append(effects.FourierGravityCompensator(self.psi[18:21], joint=1))
        return Model(robot, fx)

    def fit_common_ratio(self, posture: int = 0, bounds=(20.0, 600.0), hold="actuated", n_grid: int = 601):
        """One gear ratio for all joints reproducing the thesis' Model frequencies at ``posture``:
        the best of a log-spaced grid (one compiled sweep). Returns (r, rms relative error)."""
        from .linear import modal_analysis

        target = np.sort(self.thesis["frequency_model_Hz"][posture])
        q = self.postures[posture]
        grid = np.exp(np.linspace(np.log(bounds[0]), np.log(bounds[1]), n_grid))
        f = sweep(lambda r: modal_analysis(self.model(r * np.ones(3)), q, hold=hold).frequency,
                  grid, chunk_size=n_grid, progress=False)
        err = np.sqrt(np.mean(((np.sort(f, axis=1) - target) / target) ** 2, axis=1))
        err[~np.isfinite(err)] = np.inf
        k = int(np.argmin(err))
        return float(grid[k]), float(err[k])
