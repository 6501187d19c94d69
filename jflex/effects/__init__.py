"""Effects added to the rigid core of a model: one file per family."""

from ._base import AbstractEffect as AbstractEffect, Slots as Slots
from ._flexible_joint import FlexibleJoints as FlexibleJoints; from ._gravity_compensator import FourierGravityCompensator as FourierGravityCompensator, SpringGravityCompensator as SpringGravityCompensator
