"""The posture a log map states (``q0``: a case.yaml data set's), as the NPZ fields a
posture-carrying data set holds."""

from __future__ import annotations

import numpy as np

from .._errors import ConfigError
from ._log_map import LogMap


def yaml_posture(m: LogMap, factor: float = 1.0) -> dict:
    """The ``q0`` a log map gives (CSV modal/response, UFF frf) as NPZ fields: ``q0`` and, for a
    mapping that names joints the model lacks, ``joints``; angles times ``factor``."""
    case_file, fld = m.where
    q0 = m.q0
    names = list(m.joints)
    if isinstance(q0, dict):
        missing = [j for j in names if j not in q0]
        if missing:
            raise ConfigError(f"{case_file}: field '{fld}.q0': no angle for model joints {missing} "
                              f"(the model has joints {names})")
        return {"q0": factor * np.asarray(list(q0.values()), float), "joints": np.asarray(list(q0))}
    if len(q0) != len(names):
        raise ConfigError(f"{case_file}: field '{fld}.q0': expected {len(names)} angles (model joints {names} in "
                          f"that order), got {len(q0)}")
    return {"q0": factor * np.asarray(q0, float)}
