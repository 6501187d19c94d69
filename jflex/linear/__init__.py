"""Linear analyses at a posture: modal analysis, MAC and mode tracking, FRFs, stability lobes."""

from ._common import expand_posture as expand_posture, resolve_hold as resolve_hold, linearization as linearization
from ._qep import qep_newton as qep_newton
from ._modal import Eigen as Eigen, Modes as Modes, eigen as eigen, modes as modes, modal_analysis as modal_analysis
from ._frf import (
    PoleResidue as PoleResidue,
    frf as frf,
    frf_matrices as frf_matrices,
    half_power_damping as half_power_damping,
    modal_frf as modal_frf,
    pole_residue as pole_residue,
    pole_residue_matrices as pole_residue_matrices,
    synthesize_frf as synthesize_frf,
)
from ._frf_sweep import frf_sweep as frf_sweep
from ._mac import (best_permutation as best_permutation, mac as mac, pair_modes as pair_modes, serpentine as serpentine,
                   track_modes as track_modes)
from ._lobes import (
    Lobes as Lobes,
    directional_matrix as directional_matrix,
    immersion_angles as immersion_angles,
    stability_limit as stability_limit,
    stability_lobes as stability_lobes,
)
