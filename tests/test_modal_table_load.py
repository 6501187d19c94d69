"""A modal table's damping ratios: NaN means 'not measured'; an infinite ratio is refused."""

import numpy as np
import pytest

import jflex
from jflex.gap.case._case import _modal


@pytest.mark.parametrize("bad", [np.inf, -np.inf, 1.0, -0.01])
def test_modal_zeta_outside_its_range_is_refused(tmp_path, bad):
    robot = jflex.load_robot("staubli_tx200")
    arrs = {"q0": np.zeros(robot.nq), "freq": np.array([10.0, 20.0]), "zeta": np.array([0.02, bad])}
    with pytest.raises(jflex.DataError, match="zeta"):
        _modal(arrs, tmp_path / "modes.npz", robot)


def test_modal_zeta_nan_is_not_measured(tmp_path):
    robot = jflex.load_robot("staubli_tx200")
    arrs = {"q0": np.zeros(robot.nq), "freq": np.array([10.0, 20.0]), "zeta": np.array([0.02, np.nan])}
    out = _modal(arrs, tmp_path / "modes.npz", robot)[0]
    assert np.isnan(out["zeta"][1]) and out["zeta"][0] == 0.02
