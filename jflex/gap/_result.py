"""The result of a gap diagnosis as typed values: each candidate's held-out evaluation
(:class:`CandidateResult`), the diagnosis itself (:class:`Diagnosis`, serialised as
``diagnosis.json`` by :meth:`Diagnosis.as_dict`) and the arrays the report draws
(:class:`ReportSeries`, kept with the diagnosis and never serialised), so that a report reads a
stored result and evaluates no model."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from .judge._noise import NoiseFloor

SCHEMA_VERSION = 1  # of diagnosis.json: a new version when a key changes meaning or goes

GAP_WEIGHTING = ("torque sets: residual energy over torque-signal energy pooled over the joints, "
                 "sqrt(sum_j mse_j / sum_j std(tau_j)^2): each joint's NRMSE^2 weighs by its share of the signal "
                 "energy; channels left out of the gap excluded")
UNITS = {"gap": "NRMSE %", "noise_floor": "NRMSE %", "shrink": "% of the excess over noise closed"}


@dataclasses.dataclass(frozen=True)
class CandidateResult:
    """One candidate effect added to a model and evaluated on the held-out data: where it sits
    (``joint`` or ``link`` name, or neither), its held-out criterion ``score``, the gap after it
    [%], the share of the nominal excess over noise it closed (``shrink``, clipped to 0-100 %;
    ``shrink_raw`` of the gap itself), the gaps per data set and channel, the channels it made
    worse beyond their noise, why its fit is implausible (None when it is not), its residual
    signature (torque candidates ranked alone) and, once selected, the share of the excess before
    its step that it closed (``step_shrink``)."""

    effect: str
    joint: str | None
    link: str | None
    score: float
    gap_after: float
    shrink: float
    shrink_raw: float
    per_dataset: dict
    per_channel: dict
    worse_channels: list
    implausible: str | None = None
    signature: dict | None = None
    step_shrink: float | None = None

    def as_dict(self) -> dict:
        """The entry as ``diagnosis.json`` holds it (the optional keys only where they are set)."""
        out = dict(effect=self.effect, joint=self.joint, link=self.link, score=self.score, gap_after=self.gap_after,
                   shrink=self.shrink, shrink_raw=self.shrink_raw, per_dataset=self.per_dataset,
                   per_channel=self.per_channel, worse_channels=self.worse_channels)
        if self.implausible:
            out["implausible"] = self.implausible
        if self.signature is not None:
            out["signature"] = self.signature
        if self.step_shrink is not None:
            out["step_shrink"] = self.step_shrink
        return out


@dataclasses.dataclass(frozen=True, eq=False)
class TorqueTrace:
    """A torque validation set as the report draws it: time [s], measured torque (N, n) [N m],
    each joint's torque spread (the residual's unit) and the low-pass cutoff [Hz] of its processing."""

    name: str
    t: np.ndarray
    tau: np.ndarray
    scale: np.ndarray
    cutoff: float | None


@dataclasses.dataclass(frozen=True, eq=False)
class ResponseTrace:
    """An output-error (tip) validation set as the report draws it: time, the measured channels
    (N, k) and the nominal and final models' simulations of them."""

    name: str
    t: np.ndarray
    y: np.ndarray
    channels: tuple
    nominal: np.ndarray
    final: np.ndarray


@dataclasses.dataclass(frozen=True, eq=False)
class ReportSeries:
    """What the report's figures and tables draw beyond ``diagnosis.json``: the joint names, the
    nominal and final models' evaluations on the validation sets (``{set: {kind, nrmse, resid | Hm,
    err | ef, idx, f_model, ...}}``), the torque and output-error validation sets with their
    simulations, and the FRF/modal validation data sets. ``error``: why the simulations for the
    figures failed (no figure is drawn then)."""

    names: tuple
    nominal: dict
    final: dict
    torque: tuple = ()
    frequency: tuple = ()
    responses: tuple = ()
    error: str | None = None

    @property
    def n(self) -> int:
        return len(self.names)


@dataclasses.dataclass(frozen=True, eq=False)
class Diagnosis:
    """A gap diagnosis: every field that ``diagnosis.json`` holds (:meth:`as_dict`; ``result`` is
    that mapping), then what is kept beside it for plots and further work and never serialised:
    the loaded case, the problem, the nominal and final fitted models, the report's arrays."""

    case: str
    verdict: str
    stop_reason: str
    cad_spread: dict
    torque_scale_suspects: object
    gap_before: float
    gap_after: float
    noise_floor: float
    noise_floor_upper: float | None
    floor: NoiseFloor
    excess_before: float
    excess_after: float
    channel_gaps: dict
    excluded_channels: dict
    conditioning: dict
    vetoed: list
    shrink: float
    inertia_refit: list
    inertia: str
    cad_beyond_tolerance: dict | None
    confounded_with_inertia_refit: list
    processing: dict
    significant: bool
    remaining_significant: bool
    joints_beyond_floor: list
    test: dict
    where: list
    ranking: tuple
    selected: tuple
    ambiguous: list
    steps: list
    swapped: list
    parameters: dict
    nominal_parameters: dict
    unmatched_modes: list
    responses_output_error: list
    responses_fitted: list
    simulated_refit: dict
    responses_not_modelled: list
    failed_solves: list
    seconds: float
    # not serialised
    loaded: object = None
    problem: object = None
    nominal: object = None
    final: object = None
    series: ReportSeries | None = None

    def as_dict(self) -> dict:
        """The mapping written to ``diagnosis.json``, ``schema_version`` last."""
        fl = self.floor
        return dict(
            case=self.case, verdict=self.verdict, stop_reason=self.stop_reason, cad_spread=self.cad_spread,
            torque_scale_suspects=self.torque_scale_suspects, gap_before=self.gap_before, gap_after=self.gap_after,
            noise_floor=self.noise_floor, noise_floor_upper=self.noise_floor_upper,
            noise_floor_per_dataset=fl.per_dataset, noise_floor_source=fl.sources, noise_floor_details=fl.details,
            noise_floor_failed=fl.failed, excess_before=self.excess_before, excess_after=self.excess_after,
            gap_weighting=GAP_WEIGHTING, channel_gaps=self.channel_gaps, excluded_channels=self.excluded_channels,
            conditioning=self.conditioning, vetoed=self.vetoed, shrink=self.shrink, inertia_refit=self.inertia_refit,
            inertia=self.inertia, cad_beyond_tolerance=self.cad_beyond_tolerance,
            confounded_with_inertia_refit=self.confounded_with_inertia_refit, processing=self.processing,
            significant=self.significant, remaining_significant=self.remaining_significant,
            joints_beyond_floor=self.joints_beyond_floor, test=self.test, where=self.where,
            ranking=[e.as_dict() for e in self.ranking], selected=[e.as_dict() for e in self.selected],
            ambiguous=self.ambiguous, steps=self.steps, swapped=self.swapped, parameters=self.parameters,
            nominal_parameters=self.nominal_parameters, unmatched_modes=self.unmatched_modes,
            responses_output_error=self.responses_output_error, responses_fitted=self.responses_fitted,
            simulated_refit=self.simulated_refit, responses_not_modelled=self.responses_not_modelled,
            failed_solves=self.failed_solves, seconds=self.seconds, units=UNITS, schema_version=SCHEMA_VERSION)

    def to_json(self, **kw) -> str:
        """``diagnosis.json``'s text (:meth:`as_dict`, numpy values as plain numbers)."""
        import json

        from .._runs import _jsonable

        return json.dumps(_jsonable(self.as_dict()), **kw)

    @functools.cached_property
    def result(self) -> dict:
        """The mapping written to ``diagnosis.json`` (:meth:`as_dict`), made once: a note the
        report adds to it (a figure that failed) stays with it."""
        return self.as_dict()
