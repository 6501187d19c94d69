"""A Model of a robot with mimic joints: its coordinates are the robot's (a follower has none of
its own), and effects, which index joints as coordinates, are refused by name until supported."""

import importlib.metadata as md

import numpy as np
import pytest

import jflex


@pytest.fixture(scope="module")
def coupled_panda():
    try:
        urdf = next(f.locate() for f in md.files("example-robot-data") if f.name == "panda.urdf")
    except md.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    return jflex.load_urdf(urdf)  # fingers coupled by <mimic>: 9 joints, 8 coordinates


def test_model_coordinates_are_the_robots(coupled_panda):
    r = coupled_panda
    assert r.n_joints == r.nq + 1
    lay = jflex.Model(r).layout
    assert lay.coord_names == tuple(r.coordinate_names) and lay.nx == r.nq
    # the rigid model's mass matrix is the robot's G^T M G (no padded, singular coordinate)
    q = np.random.default_rng(0).uniform(-0.5, 0.5, r.nq)
    q[-1] = 0.02
    lin = jflex.linearize(jflex.Model(r), np.asarray(q))
    np.testing.assert_allclose(np.asarray(lin.M), np.asarray(jflex.crba(r, q)), rtol=1e-10, atol=1e-12)


def test_effects_on_a_coupled_robot_are_refused(coupled_panda):
    with pytest.raises(jflex.ParameterError, match="mimic joints.*panda_finger_joint2"):
        jflex.Model(coupled_panda, [jflex.effects.JointFriction(["panda_joint1"], viscous=1.0)])
