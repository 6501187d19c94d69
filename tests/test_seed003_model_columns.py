"""jflex's flexible-joint models of the Staubli TX200 and Kuka KR90 of the MASc thesis "Posture
Dependent Dynamics in Robotic Machining" against the thesis' own Model columns (Tables 4.5 and
4.6), and mode pairing that survives close modes.

The thesis values are typed here from the tables (not read from the configs): the per-joint
reflected rotor inertias in the configs were fitted to configuration 1 only, so configurations
2 and 3 are an independent check of the model (base parameters, Eq. 4.6, compensator, K).
"""

import pathlib
import sys

import jax
import numpy as np
import pytest

import jflex
from jflex.linear import pair_modes

ROOT = pathlib.Path(__file__).resolve().parent.parent

# the thesis' robot model is a sibling module of the experiments that use it
sys.path.insert(0, str(ROOT / "experiments"))
from _machining_robot import MachiningRobot  # noqa: E402

TOL_PCT = 1.0  # every mode within 1 % of the thesis' Model column

# Model column f_r [Hz], rows in the tables' order (by mode shape), per configuration.
THESIS_MODEL_HZ = {
    # the thesis' Table 4.5 (Staubli TX200), "Model" column, configurations 1-3, rows 1-3 each
    "staubli_tx200": [[9.236, 12.48, 24.03], [7.46, 11.17, 29.19], [8.09, 11.96, 25.42]],
    # the thesis' Table 4.6 (Kuka KR90), "Model" column, configurations 1-3, rows 1-3 each: in
    # configurations 2 and 3 row 1 (14.6, 14.2 Hz) lies above row 2 (10.9, 13 Hz), the shape of
    # configuration 1's first mode having moved above its second
    "kuka_kr90": [[10.0, 11.0, 23.7], [14.6, 10.9, 23.7], [14.2, 13.0, 21.7]],
}


def _modes(name):
    rob = MachiningRobot.from_config(ROOT / "configs" / "seed003" / f"{name}.yaml")
    model, _ = rob.configured_model()
    modes = jax.jit(jax.vmap(lambda q: jflex.modal_analysis(model, q, hold="actuated")))(rob.postures)
    return rob, np.asarray(modes.frequency), np.asarray(modes.shape)


@pytest.fixture(scope="module", params=sorted(THESIS_MODEL_HZ))
def robot_modes(request):
    return request.param, *_modes(request.param)


def test_model_columns_within_one_percent(robot_modes):
    """Rows paired with configuration 1's shapes (the tables label rows by shape); every mode of
    every configuration within 1 % of the thesis' Model value."""
    name, rob, f, shapes = robot_modes
    th = np.asarray(THESIS_MODEL_HZ[name])
    for k in range(3):
        idx, macs = pair_modes(shapes[0], shapes[k], f[0], f[k])
        err = 100 * (f[k][idx] - th[k]) / th[k]
        assert np.all(np.abs(err) < TOL_PCT), f"{name} configuration {k + 1}: errors {err.round(2)} %"
        assert np.all(macs > 0.7), f"{name} configuration {k + 1}: pairs with low MAC {macs.round(2)}"


def test_kuka_close_modes_not_swapped():
    """KR90 configurations 2-3: pairing with configuration 1's shapes puts the ~14 Hz mode in row
    1, as Table 4.6 does; pairing by frequency order (or step-wise path tracking) put the
    ~11 Hz mode there, 26 % off the thesis row."""
    rob, f, shapes = _modes("kuka_kr90")
    for k in (1, 2):
        idx, _ = pair_modes(shapes[0], shapes[k], f[0], f[k])
        assert sorted(idx.tolist()) == [0, 1, 2]
        assert f[k][idx[0]] > f[k][idx[1]], f"configuration {k + 1}: row 1 {f[k][idx[0]]:.2f} Hz, row 2 {f[k][idx[1]]:.2f} Hz"
        order = np.argsort(f[k])  # frequency order would pair row 1 with the lowest mode
        assert order[0] != idx[0]


def test_pair_modes_follows_shapes_of_close_modes():
    """Two modes 0.5 % apart whose shapes trade places (and whose frequencies trade order): the
    pairing follows the shapes, not the frequency order."""
    e = np.eye(3)
    ref = np.stack([e[0] + 0.1 * e[2], e[1], e[2]], axis=1)
    f_ref = np.array([10.0, 10.05, 30.0])
    cur = np.stack([e[1] + 0.05 * e[2], e[0], e[2] + 0.02 * e[0]], axis=1)  # ref 0 is now column 1
    f_cur = np.array([9.98, 10.03, 29.0])
    idx, macs = pair_modes(ref, cur, f_ref, f_cur)
    np.testing.assert_array_equal(idx, [1, 0, 2])
    assert np.all(macs > 0.9)


def test_pair_modes_frequency_breaks_a_shape_tie():
    """Shapes that cannot tell two modes apart (both at 45 deg between the references: MAC 0.5
    each) are paired by frequency; one-to-one, more model modes than references allowed."""
    e = np.eye(3)
    ref = e[:, :2]
    cur = np.stack([e[0] + e[1], e[0] - e[1], e[2]], axis=1)
    idx, macs = pair_modes(ref, cur, [10.0, 12.0], [12.1, 9.9, 11.0])
    np.testing.assert_array_equal(idx, [1, 0])
    np.testing.assert_allclose(macs, 0.5)
    with pytest.raises(jflex.ShapeError):
        pair_modes(cur, ref)
