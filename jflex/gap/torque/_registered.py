"""Effects that offer themselves as candidates (:func:`jflex.effects.register_candidate`) as torque
terms: their columns are the effect's own regressor."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ..._program_cache import persistent_jit
from ...effects._linear import CandidateInfo, registered_candidates
from ._plausible import data_scale
from ._set import TorqueSet, TorqueTerm, fit_terms, on_rows


@persistent_jit
def _effect_columns(effect, robot, q, qd, qdd):
    return jax.vmap(lambda a, b, c: effect.regressor(robot, a, b, c))(q, qd, qdd)


@dataclasses.dataclass(frozen=True)
class RegisteredTerm(TorqueTerm):
    """A candidate effect class of :mod:`jflex.effects` that registered itself
    (:func:`jflex.effects.register_candidate`), at the placement whose first joint is ``joint``;
    ``hyper`` its held nonlinear parameter (searched on the class's grid). Its columns are the
    effect's own regressor (the Jacobian of the torque its law adds)."""

    effect: str
    joint: int | None = None
    hyper: object = None

    @property
    def info(self) -> CandidateInfo:
        return registered_candidates()[self.effect].candidate

    @property
    def signature(self) -> str:
        return self.info.signature

    def group(self, n: int) -> tuple:
        """The joint indices of its placement on an ``n``-joint robot."""
        info = self.info
        if info.per_joint_law:
            return (self.joint,)
        hit = [g for g in info.placements(n) if g[0] == self.joint]
        if hit:
            return tuple(hit[0])
        # placed by the user (a nominal effect) where the class does not try it: the next joints
        return tuple(range(min(self.joint, n - info.size), min(self.joint, n - info.size) + info.size))

    def build(self, robot, joints=None):
        names = tuple(robot.joint_names)
        return self.info.build(tuple(names[j] for j in (self.group(len(names)) if joints is None else joints)), self.hyper)

    def param_names(self):
        proto = self.info.build(tuple(f"_{i}" for i in range(self.info.size)), self.hyper)
        owners = proto.parameter_owners(None)
        leaves = [a for a in proto.linear_leaves for _ in range(int(np.prod(np.shape(getattr(proto, a)))))]
        return [(o.split(":", 1)[1] + "." if ":" in o else "") + f"{a} [{u}]"
                for o, a, u in zip(owners, leaves, proto.parameter_units())]

    def bounds(self):
        lo = 0.0 if self.info.nonnegative else -np.inf
        return [lo] * self.n_params, [np.inf] * self.n_params

    def label(self, joint_names) -> str:
        if self.joint is None or self.info.per_joint_law:
            return super().label(joint_names)
        return f"{self.effect}@" + "+".join(joint_names[j] for j in self.group(len(joint_names)))

    def columns(self, s: TorqueSet) -> np.ndarray:
        robot, n = s.robot, s.q.shape[1]
        whole = self.info.per_joint_law  # one effect on every joint gives every placement's columns
        key = ("registered", self.effect, None if whole else self.group(n), self.hyper)
        if key not in s.cache:
            eff = self.build(robot, tuple(range(n)) if whole else None)
            Y = on_rows(_effect_columns, (eff, robot), (s.q, s.qd, s.qdd))
            s.cache[key] = (Y, np.asarray(eff.parameter_joints(robot)))
        Y, owner = s.cache[key]
        return Y[:, :, owner == self.joint] if whole else Y

    def parameters(self, theta) -> dict:
        out = super().parameters(theta)
        if self.info.hyper is not None:
            out[self.info.hyper[1]] = float(self.hyper)
        return out

    def search(self, base_terms, base_delay, sets, inertia=None):
        if self.info.hyper is None:
            return super().search(base_terms, base_delay, sets, inertia)
        fits = [fit_terms(tuple(base_terms) + (dataclasses.replace(self, hyper=v),), base_delay, sets, inertia)
                for v in self.info.hyper[0]]
        return min(fits, key=lambda f: f.cost)

    def probes(self):
        # the residual is correlated with the columns at every grid value (a coupling's sign and
        # ratio are what the signature must not presume)
        if self.info.hyper is None:
            return (self,)
        return tuple(dataclasses.replace(self, hyper=v) for v in self.info.hyper[0])

    def contribute(self, parts, theta) -> None:
        parts.extra.append(self.build(parts.robot).with_parameters(np.asarray(theta, float)))

    def implausible(self, theta, sets):
        if not sets:
            return None
        robot = sets[0].robot
        return self.build(robot).implausible(robot, theta, data_scale(sets))
