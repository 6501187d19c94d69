"""Planar finite elements for linkages and kineto-elastodynamics.

"The press paper" in this package is "Elastic dynamic research of high-speed multi-link precision press considering structural stiffness of rotation joints"
(a high-speed multi-link press; equation and section numbers refer to it).

Beam elements with axial stretch, bar elements for joint stiffness, lumped masses and assembly
by connectivity; modes, Rayleigh and modal damping; rigid-body motion of closed-loop linkages
from their loop-closure equations; the elastic response to the inertial loads of that motion by
modal superposition (periodic steady state or transient) and by direct (Newmark) integration.
Assembled ``M``, ``K`` and ``C`` are plain JAX arrays, so any analysis taking ``(M, C, K)`` applies.
"""

from ._assembly import (
    FEModel as FEModel,
    Modes as Modes,
    fe_model as fe_model,
    modal_damping as modal_damping,
    modes as modes,
    rayleigh_coefficients as rayleigh_coefficients,
    rayleigh_damping as rayleigh_damping,
)
from ._elements import (
    bar_matrices as bar_matrices,
    beam_local_mass as beam_local_mass,
    beam_local_stiffness as beam_local_stiffness,
    beam_matrices as beam_matrices,
    beam_rotation as beam_rotation,
    bimodular_modulus as bimodular_modulus,
)
from ._ked import (
    AbstractDamping as AbstractDamping,
    KEDResponse as KEDResponse,
    ModalDamping as ModalDamping,
    RayleighDamping as RayleighDamping,
    ked_periodic as ked_periodic,
    ked_transient as ked_transient,
    newmark as newmark,
    pose_modes as pose_modes,
)
from ._linkage import (
    LinkageMotion as LinkageMotion,
    linkage_motion as linkage_motion,
    motion_derivatives as motion_derivatives,
    point_motion as point_motion,
    solve_loop_closure as solve_loop_closure,
)
from ._press import (
    JOINTS as PRESS_JOINTS,
    MEMBERS as PRESS_MEMBERS,
    POINTS as PRESS_POINTS,
    PressFE as PressFE,
    PressGeometry as PressGeometry,
    PressPoses as PressPoses,
    press_fe as press_fe,
    press_from_config as press_from_config,
    press_motion as press_motion,
    press_points as press_points,
    press_poses as press_poses,
    press_q_bdc as press_q_bdc,
    press_residual as press_residual,
    spm_to_rad_s as spm_to_rad_s,
)
