"""Sim-to-real gap diagnosis: where the gap lies, which unmodelled effect causes it,
how far it shrinks once that effect is added and refitted, judged on held-out data."""

from .case._case import Case as Case, Dataset as Dataset, EFFECT_NAMES as EFFECT_NAMES, load_case as load_case
from .case._init import case_init as case_init
from ._diagnose import diagnose as diagnose
from ._result import Diagnosis as Diagnosis
from ._effect_term import EffectCandidate as EffectCandidate
from .judge._noise import NoiseFloor as NoiseFloor, noise_floor as noise_floor, repeats_factor as repeats_factor, robust_sigma as robust_sigma
from .judge._periodic import find_period as find_period
from .judge._selection import (
    EXPLAINED_FLOOR_FACTOR as EXPLAINED_FLOOR_FACTOR,
    EXPLAINED_SHRINK as EXPLAINED_SHRINK,
    FAMILY_ALPHA as FAMILY_ALPHA,
    MIN_GAP as MIN_GAP,
    MIN_NAMED_SHRINK as MIN_NAMED_SHRINK,
    MIN_STEP_SHRINK as MIN_STEP_SHRINK,
    SIGNIFICANCE as SIGNIFICANCE,
    Selection as Selection,
    Step as Step,
    DECISIVE_SCORE as DECISIVE_SCORE,
    decisive as decisive,
    forward_select as forward_select,
    gap_summary as gap_summary,
    gap_uncertainty as gap_uncertainty,
    ic_delta as ic_delta,
    is_significant as is_significant,
    pooled_upper as pooled_upper,
    rank_entries as rank_entries,
    significance_factor as significance_factor,
    remaining_small as remaining_small,
    step_record as step_record,
    verdict as verdict,
    resolved_channels as resolved_channels,
    vetoed as vetoed,
    worse_channels as worse_channels,
)
from .report._report import write_report as write_report
from ._demo import demo as demo
