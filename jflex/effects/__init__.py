"""Effects added to the rigid core of a model: one file per family."""

from ._base import AbstractEffect as AbstractEffect, Slots as Slots
from ._flexible_joint import FlexibleJoints as FlexibleJoints; from ._gravity_compensator import FourierGravityCompensator as FourierGravityCompensator, SpringGravityCompensator as SpringGravityCompensator
from ._damping import (AbstractDampingLaw as AbstractDampingLaw, KelvinVoigt as KelvinVoigt, complex_modulus as complex_modulus, damping_laws as damping_laws, StructuralDamping as StructuralDamping, ViscousDamping as ViscousDamping, coordinate_indices as coordinate_indices, rayleigh_damping as rayleigh_damping)  # noqa: E501
from ._fractional import Fractional as Fractional, grunwald_letnikov as grunwald_letnikov, oustaloup as oustaloup, oustaloup_response as oustaloup_response
from ._hysteresis import Hysteretic as Hysteretic, masing_force as masing_force, virgin_curve as virgin_curve
from ._friction import AsymmetricCoulomb as AsymmetricCoulomb, JointFriction as JointFriction
from ._linear import (AbstractLinearEffect as AbstractLinearEffect, CandidateInfo as CandidateInfo, DataScale as DataScale, effect_torque as effect_torque, register_candidate as register_candidate, registered_candidates as registered_candidates)  # noqa: E501
from ._torque_offset import TorqueOffset as TorqueOffset
from ._coupled_drive import CoupledDrive as CoupledDrive
from ._flexible_link import FlexibleLink as FlexibleLink
from ._spring import Spring as Spring
from ._rigid_additions import Payload as Payload, RotorInertia as RotorInertia
from ._measured_joint import (Backlash as Backlash, DriveGain as DriveGain, JointCompliance as JointCompliance, SensorDelay as SensorDelay, compliance_deflection as compliance_deflection, delayed as delayed, first_order_zero_phase as first_order_zero_phase, loaded_play_side as loaded_play_side, play as play, scaled_torque as scaled_torque)  # noqa: E501
from ._registry import EFFECT_NAMES as EFFECT_NAMES, EFFECTS as EFFECTS
