"""jflex: differentiable dynamics and identification of flexible manipulators, in JAX.

A model is a rigid core (:class:`Robot`) plus effects; every analysis consumes that model.
Everything runs in float64 unless ``JFLEX_X64=0`` is set before import.
"""

import importlib.metadata as _md
import os as _os

# XLA:CPU's new fusion emitters recompute shared subexpressions of long elementwise graphs
# (the rigid-body kernels, MuJoCo MJX) and run them up to 1000x slower (see DESIGN.md and
# benchmarks/bench_dynamics.py). The legacy emitters do not. The flag only takes effect if set
# before JAX starts its CPU backend; JFLEX_XLA_FLAGS=0 leaves XLA_FLAGS untouched.
if _os.environ.get("JFLEX_XLA_FLAGS", "1") != "0" and "xla_cpu_use_fusion_emitters" not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " --xla_cpu_use_fusion_emitters=false").strip()

import jax as _jax

try:  # warn when JAX's CPU backend started before the flag could apply (private API)
    from jax._src import xla_bridge as _xb
except Exception:
    _xb = None
if _xb is not None and getattr(_xb, "_backends", None) and _os.environ.get("JFLEX_XLA_FLAGS", "1") != "0":
    import warnings as _warnings

    _warnings.warn(
        "jflex was imported after JAX initialised its backend, so XLA_FLAGS="
        "--xla_cpu_use_fusion_emitters=false could not take effect; rigid-body kernels may run far "
        "slower on CPU. Import jflex first, or set that flag yourself.",
        stacklevel=2,
    )

if _os.environ.get("JFLEX_X64", "1") != "0":
    _jax.config.update("jax_enable_x64", True)

try:
    __version__ = _md.version("jflex")
except _md.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0"

from ._errors import (
    ConfigError as ConfigError,
    DataError as DataError,
    JFlexError as JFlexError,
    ParameterError as ParameterError,
    ShapeError as ShapeError,
    SolverError as SolverError,
    URDFError as URDFError,
)
from ._runs import (
    experiment_cli as experiment_cli,
    load_yaml as load_yaml,
    make_run_dir as make_run_dir,
    write_results as write_results,
)
from ._robot import Robot as Robot, make_robot as make_robot, check_inertia as check_inertia
from ._dh import from_dh as from_dh
from ._urdf import load_urdf as load_urdf, from_urdf_string as from_urdf_string
from ._dynamics import (
    aba as aba,
    crba as crba,
    forward_dynamics as forward_dynamics,
    forward_kinematics as forward_kinematics,
    frame_placement as frame_placement,
    gravity as gravity,
    jacobian as jacobian,
    kinetic_energy as kinetic_energy,
    nonlinear_effects as nonlinear_effects,
    potential_energy as potential_energy,
    regressor as regressor,
    rnea as rnea,
)
from . import effects as effects
from ._model import (
    Layout as Layout,
    Linearization as Linearization,
    Model as Model,
    bias_forces as bias_forces,
    dynamic_stiffness as dynamic_stiffness,
    gravity_stiffness as gravity_stiffness,
    initial_state as initial_state,
    input_matrix as input_matrix,
    linearize as linearize,
    mass_matrix as mass_matrix,
    model_forward_dynamics as model_forward_dynamics,
    model_inverse_dynamics as model_inverse_dynamics,
    state_rate as state_rate,
)
from ._sweep import batched as batched, sweep as sweep
from ._allocator import tune_allocator as tune_allocator
from ._config import (
    available_robots as available_robots,
    load_robot as load_robot,
    robot_from_config as robot_from_config,
)
from . import linear as linear
from .linear import (
    frf as frf,
    frf_sweep as frf_sweep,
    mac as mac,
    modal_analysis as modal_analysis,
    stability_lobes as stability_lobes,
    track_modes as track_modes,
)
from . import fem as fem
from ._inputs import (  # time responses (issue 4)
    AbstractInput as AbstractInput, Brake as Brake, Chirp as Chirp, Function as Function, Ramp as Ramp,
    Sampled as Sampled, Step as Step, Zero as Zero,
)
from ._simulate import Response as Response, simulate as simulate, total_energy as total_energy
from ._beam import (
    Beam as Beam, beam_modal_matrices as beam_modal_matrices, beam_roots as beam_roots,
    clamped_free_frequencies as clamped_free_frequencies, make_beam as make_beam,
)
from ._lagrangian import (
    lagrangian_bias as lagrangian_bias, lagrangian_forward_dynamics as lagrangian_forward_dynamics,
    lagrangian_mass_matrix as lagrangian_mass_matrix,
)

# identification (issue 5): equation-error and output-error fits, EMA helpers
from . import identify as identify
from . import gap as gap  # sim-to-real gap diagnosis (issue 6)
from ._seed003 import (
    appendix_b_columns as seed003_appendix_b_columns,
    realisation_matrix as seed003_realisation_matrix,
    Seed003Robot as Seed003Robot,
)
