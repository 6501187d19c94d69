"""What the judges read of a diagnosed problem, a candidate and a model: structural types that
:class:`jflex.gap._problem.Problem`, ``Candidate`` and ``State`` satisfy. The problem builds on the
judges (the noise floor, the degenerate-data checks), so the judges name what they read here
instead of importing it."""

from __future__ import annotations

from typing import Protocol

import numpy as np


class ProblemView(Protocol):
    """A case's prepared data as the judges read them: the joint names, the torque training and
    validation sets, the output-error validation sets, the user's candidates and the inertial prior."""

    names: tuple
    n: int
    ttrain: list
    tval: list
    rval: list
    user: dict
    inertia: object

    def included(self, name: str) -> np.ndarray:
        """(n,) bool: the torque channels of set ``name`` that enter the gap."""


class CandidateView(Protocol):
    """An effect placed at a joint or link (index), or nowhere (None)."""

    effect: str
    joint: int | None


class StateView(Protocol):
    """A model under diagnosis: its fitted torque terms."""

    tfit: object
