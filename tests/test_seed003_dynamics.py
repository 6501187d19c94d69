"""The Appendix-B regressor of the MASc thesis "Posture Dependent Dynamics in Robotic Machining"
(the thesis' own M(q), G(q) in base parameters) is reproduced by jflex's rigid-body regressor on
the Table 2.2/2.3 kinematics: an independent check of both."""

import pathlib
import sys

import numpy as np
import pytest

import jflex

ROOT = pathlib.Path(__file__).resolve().parent.parent

# the thesis' robot model is a sibling module of the experiments that use it
sys.path.insert(0, str(ROOT / "experiments"))
from _machining_robot import appendix_b_columns, realisation_matrix  # noqa: E402


@pytest.mark.parametrize("name", ["staubli_tx200", "kuka_kr90"])
def test_appendix_b_realised_by_jflex_regressor(name):
    robot = jflex.load_robot(name)
    a1, a2 = float(robot.placement_p[1, 0]), float(robot.placement_p[2, 0])
    R, rel = realisation_matrix(robot, a1, a2)
    assert rel.max() < 1e-10
    rng = np.random.default_rng(7)  # fresh samples, not those of the fit
    for _ in range(5):
        q, qdd = rng.uniform(-np.pi, np.pi, 3), rng.normal(size=3)
        Y = np.asarray(jflex.regressor(robot, q, np.zeros(3), qdd))
        np.testing.assert_allclose(Y @ R, appendix_b_columns(q, qdd, a1, a2), atol=1e-9)
