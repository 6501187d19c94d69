"""jflex: differentiable dynamics and identification of flexible manipulators, in JAX.

A model is a rigid core (:class:`Robot`) plus effects; every analysis consumes that model.
Everything runs in float64 unless ``JFLEX_X64=0`` is set before import.

Public names are loaded on first use (PEP 562): ``import jflex`` costs little beyond ``import
jax``, and ``jflex.gap``, ``jflex.identify``, ... (SciPy, diffrax, optimistix, matplotlib) load
when first touched. ``_LAZY`` below is the table of what lives where.
"""

import importlib.metadata as _md
import os as _os
import typing as _typing

# XLA:CPU's new fusion emitters recompute shared subexpressions of long elementwise graphs
# (the rigid-body kernels, MuJoCo MJX) and run them up to 1000x slower (measured in
# benchmarks/bench_dynamics.py). The legacy emitters do not. The flag only takes effect if set
# before JAX starts its CPU backend; JFLEX_XLA_FLAGS=0 leaves XLA_FLAGS untouched. jaxlib 0.11
# no longer has the flag, and XLA aborts the process on a flag it does not know (seen with
# jaxlib 0.11.2 on a GPU machine), so it is set only for the jaxlib releases that have it.


def _jaxlib_has_fusion_emitter_flag() -> bool:
    try:
        major, minor = (int(x) for x in _md.version("jaxlib").split(".")[:2])
    except (_md.PackageNotFoundError, ValueError):
        return False
    return (major, minor) < (0, 11)


_SET_XLA_FLAG = (_os.environ.get("JFLEX_XLA_FLAGS", "1") != "0" and _jaxlib_has_fusion_emitter_flag()
                 and "xla_cpu_use_fusion_emitters" not in _os.environ.get("XLA_FLAGS", ""))
if _SET_XLA_FLAG:
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " --xla_cpu_use_fusion_emitters=false").strip()

import jax as _jax

try:  # warn when JAX's CPU backend started before the flag could apply (private API)
    from jax._src import xla_bridge as _xb
except Exception:
    _xb = None
if _xb is not None and getattr(_xb, "_backends", None) and _SET_XLA_FLAG:
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

# public name -> (private module, attribute there); a module given as "" is the subpackage itself
_LAZY_MODULES = {
    "._runs": ("experiment_cli", "load_yaml", "make_run_dir", "write_results"),
    "._robot": ("Robot", "make_robot", "check_inertia"),
    "._dh": ("from_dh",),
    "._urdf": ("load_urdf", "from_urdf_string"),
    "._dynamics": (
        "aba", "crba", "forward_dynamics", "forward_kinematics", "frame_placement", "gravity", "jacobian",
        "kinetic_energy", "nonlinear_effects", "potential_energy", "regressor", "rnea",
    ),
    "._model": (
        "Layout", "Linearization", "Model", "bias_forces", "dynamic_stiffness", "gravity_stiffness",
        "initial_state", "input_matrix", "linearize", "mass_matrix", "model_forward_dynamics",
        "model_inverse_dynamics", "state_rate",
    ),
    "._sweep": ("batched", "sweep"),
    "._derivatives": ("aba_derivatives", "rnea_derivatives"),
    "._allocator": ("tune_allocator",),
    "._compilation_cache": ("enable_compilation_cache",),
    "._config": ("available_robots", "load_robot", "robot_from_config"),
    ".linear": ("frf", "frf_sweep", "mac", "modal_analysis", "stability_lobes", "track_modes"),
    "._inputs": ("AbstractInput", "Brake", "Chirp", "Function", "Ramp", "Sampled", "Step", "Zero"),  # time responses
    "._simulate": ("Response", "simulate", "total_energy"),
    "._beam": ("Beam", "beam_modal_matrices", "beam_roots", "clamped_free_frequencies", "make_beam"),
    "._lagrangian": ("lagrangian_bias", "lagrangian_forward_dynamics", "lagrangian_mass_matrix"),
}
_LAZY = {name: (mod, name) for mod, names in _LAZY_MODULES.items() for name in names}
# subpackages: effects, linear/FRF, FEM, identification, sim-to-real gap diagnosis
_LAZY.update({name: ("." + name, "") for name in ("effects", "linear", "fem", "identify", "gap")})

__all__ = sorted(
    ["ConfigError", "DataError", "JFlexError", "ParameterError", "ShapeError", "SolverError", "URDFError"]
    + list(_LAZY)
)


def __getattr__(name):
    try:
        mod, attr = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'jflex' has no attribute '{name}'") from None
    import importlib

    module = importlib.import_module(mod, __name__)
    value = getattr(module, attr) if attr else module
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


if _typing.TYPE_CHECKING:  # static tools see the eager imports
    from . import effects, fem, gap, identify, linear
    from ._allocator import tune_allocator
    from ._compilation_cache import enable_compilation_cache
    from ._beam import Beam, beam_modal_matrices, beam_roots, clamped_free_frequencies, make_beam
    from ._config import available_robots, load_robot, robot_from_config
    from ._dh import from_dh
    from ._dynamics import (
        aba, crba, forward_dynamics, forward_kinematics, frame_placement, gravity, jacobian, kinetic_energy,
        nonlinear_effects, potential_energy, regressor, rnea,
    )
    from ._inputs import AbstractInput, Brake, Chirp, Function, Ramp, Sampled, Step, Zero
    from ._lagrangian import lagrangian_bias, lagrangian_forward_dynamics, lagrangian_mass_matrix
    from ._model import (
        Layout, Linearization, Model, bias_forces, dynamic_stiffness, gravity_stiffness, initial_state,
        input_matrix, linearize, mass_matrix, model_forward_dynamics, model_inverse_dynamics, state_rate,
    )
    from ._robot import Robot, check_inertia, make_robot
    from ._runs import experiment_cli, load_yaml, make_run_dir, write_results
    from ._simulate import Response, simulate, total_energy
    from ._sweep import batched, sweep
    from ._urdf import from_urdf_string, load_urdf
    from .linear import frf, frf_sweep, mac, modal_analysis, stability_lobes, track_modes
