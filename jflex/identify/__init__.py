"""Identification: equation-error (regressor least squares, base parameters, excitation design,
physically consistent estimates) and output-error fits with optimistix, plus EMA helpers.

Names load on first use (PEP 562), so ``import jflex.identify`` costs little: ``ols`` brings in
SciPy's linear algebra only, ``lscf`` SciPy's signal tools, ``fit`` optimistix, and so on.
"""

import typing as _typing

# module -> public names it defines (the data layer's checks and signal tools among them)
_LAZY_MODULES = {
    "..data._validate": ("check_finite", "check_lengths", "check_shape", "check_time",),
    "..data._npz": ("load_npz",),
    "..data._signal": ("fft_lowpass", "spectral_derivatives",),
    "._regressor": ("Regressor", "random_samples",),
    "._base_params": ("BaseParameters", "base_parameters",),
    "._ls": ("LSResult", "instrumental_variables", "ols", "wls",),
    "._physical": ("PhysicalResult", "inertia_to_log_cholesky", "is_consistent", "log_cholesky_pseudo_inertia", "log_cholesky_to_inertia", "physical_fit", "pseudo_inertia_to_params",),
    "._excitation": ("ExcitationResult", "FourierTrajectory", "design_excitation",),
    "._fit": ("AbstractData", "AbstractTransform", "Bounded", "FitResult", "Free", "Identity", "Log", "MultiStart", "ParameterSpec", "fit", "levenberg_marquardt", "residual_vector",),
    "._residuals": ("FRFData", "ModalData", "TimeData", "TorqueData", "model_modes",),
    "._frf_jacobian": ("sparse_frf_residual",),
    "._ema": ("FRFEstimate", "LSCFResult", "frf_estimate", "lscf", "modal_residues", "peak_picking", "stable_modes",),
    "._uff": ("UFF58", "read_uff58", "write_uff58",),
}
_LAZY = {name: mod for mod, names in _LAZY_MODULES.items() for name in names}
__all__ = sorted(_LAZY)


def __getattr__(name):
    try:
        mod = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'jflex.identify' has no attribute '{name}'") from None
    import importlib

    value = getattr(importlib.import_module(mod, __name__), name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


if _typing.TYPE_CHECKING:  # static tools see the eager imports
    """Identification: equation-error (regressor least squares, base parameters, excitation design,
    physically consistent estimates) and output-error fits with optimistix, plus EMA helpers."""
    
    from ..data._validate import (
        check_finite as check_finite,
        check_lengths as check_lengths,
        check_shape as check_shape,
        check_time as check_time,
    )
    from ..data._npz import load_npz as load_npz
    from ..data._signal import fft_lowpass as fft_lowpass, spectral_derivatives as spectral_derivatives
    from ._regressor import Regressor as Regressor, random_samples as random_samples
    from ._base_params import BaseParameters as BaseParameters, base_parameters as base_parameters
    from ._ls import LSResult as LSResult, instrumental_variables as instrumental_variables, ols as ols, wls as wls
    from ._physical import (
        PhysicalResult as PhysicalResult,
        inertia_to_log_cholesky as inertia_to_log_cholesky,
        is_consistent as is_consistent,
        log_cholesky_pseudo_inertia as log_cholesky_pseudo_inertia,
        log_cholesky_to_inertia as log_cholesky_to_inertia,
        physical_fit as physical_fit,
        pseudo_inertia_to_params as pseudo_inertia_to_params,
    )
    from ._excitation import (
        ExcitationResult as ExcitationResult,
        FourierTrajectory as FourierTrajectory,
        design_excitation as design_excitation,
    )
    from ._fit import (
        AbstractData as AbstractData,
        AbstractTransform as AbstractTransform,
        Bounded as Bounded,
        FitResult as FitResult,
        Free as Free,
        Identity as Identity,
        Log as Log,
        MultiStart as MultiStart,
        ParameterSpec as ParameterSpec,
        fit as fit,
        levenberg_marquardt as levenberg_marquardt,
        residual_vector as residual_vector,
    )
    from ._residuals import (
        FRFData as FRFData,
        ModalData as ModalData,
        TimeData as TimeData,
        TorqueData as TorqueData,
        model_modes as model_modes,
    )
    from ._frf_jacobian import sparse_frf_residual as sparse_frf_residual
    from ._ema import (
        FRFEstimate as FRFEstimate,
        LSCFResult as LSCFResult,
        frf_estimate as frf_estimate,
        lscf as lscf,
        modal_residues as modal_residues,
        peak_picking as peak_picking,
        stable_modes as stable_modes,
    )
    from ._uff import UFF58 as UFF58, read_uff58 as read_uff58, write_uff58 as write_uff58
