"""Sim-to-real gap diagnosis (issue 6): where the gap lies, which unmodelled effect causes it,
how far it shrinks once that effect is added and refitted, judged on held-out data."""

from ._case import Case as Case, Dataset as Dataset, EFFECT_NAMES as EFFECT_NAMES, load_case as load_case
from ._diagnose import Diagnosis as Diagnosis, diagnose as diagnose
from ._effect_term import EffectCandidate as EffectCandidate
from ._report import write_report as write_report
from ._demo import demo as demo
from ._bench import run_bench as run_bench
