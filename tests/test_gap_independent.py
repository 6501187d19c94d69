"""The independent gap-bench generator (benchmarks/gap/independent): what it writes is what a
user's case holds, and its physics agrees with Pinocchio and with its own closed forms."""

import json
import pathlib
import sys

import numpy as np
import pinocchio as pin
import pytest

import jflex

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "gap"))
from independent import make_case  # noqa: E402
from independent import frf as F  # noqa: E402
from independent import robots as R  # noqa: E402
from independent import signals as S  # noqa: E402

RNEA_TOL = 1e-8  # [N m] two implementations of the same inverse dynamics


@pytest.mark.parametrize("name", ["arm3", "ur5", "panda"])
def test_written_urdf_is_the_pinocchio_robot(tmp_path, name):
    # the case's robot file, loaded by jflex, has the dynamics and tool frame of the Pinocchio model
    model, tool, home = R.true_model(name)
    p = tmp_path / "robot.urdf"
    p.write_text(R.urdf_text(model, tool, name))
    robot = jflex.load_urdf(p)
    rng = np.random.default_rng(0)
    data = model.createData()
    for _ in range(3):
        q, v, a = home + rng.normal(size=model.nq) * 0.3, rng.normal(size=model.nq), rng.normal(size=model.nq)
        np.testing.assert_allclose(np.asarray(jflex.rnea(robot, q, v, a)), pin.rnea(model, data, q, v, a), atol=RNEA_TOL)


def test_null_torque_case_is_angle_only_and_quantised(tmp_path):
    folder, truth = make_case(tmp_path / "null", kind="torque", robot="arm3", effects=(), seed=3, small=True)
    case = jflex.gap.load_case(folder)
    assert truth["family"] == "null" and truth["expected_verdict"] == "within_noise"
    step = truth["realism"]["encoder_step_rad"]
    for d in case.datasets:
        with np.load(d.file) as z:
            assert set(z.files) == {"t", "q", "tau"}
            k = z["q"] / step
            np.testing.assert_allclose(k, np.round(k), atol=1e-6)
    # the nominal robot is the CAD one: masses off by 2-10 % from the truth
    for link in truth["cad_error"]:
        assert 0.02 <= abs(link["mass_cad"] / link["mass_true"] - 1) <= 0.10
    assert "truth.json" not in (folder / "case.yaml").read_text()


def test_h1_estimate_matches_the_linear_model():
    # H1 of a lightly damped two-coordinate system against its exact receptance (no noise)
    model, tool, home = R.true_model("arm3")
    m, fid, act, virt = F.augment(model, tool)
    M = np.diag(pin.crba(model, model.createData(), home))
    joint = [dict(k=(2 * np.pi * f) ** 2 * Mi, c=2 * 0.05 * np.sqrt((2 * np.pi * f) ** 2 * Mi * Mi), B=0.5 * Mi,
                  kp=30 * (2 * np.pi * f) ** 2 * Mi, kd=np.sqrt(30) * (2 * np.pi * f) * Mi) for f, Mi in zip((10, 15, 25), M)]
    lin = F.Linear(m, fid, act, virt, home, joint)
    f, H1 = S.h1_frf(lin.frf, 128.0, 2**16, 2048, np.random.default_rng(1), 0.0, 0.0)
    band = (f > 5) & (f < 40)
    H = lin.frf(f[band])
    err = np.sqrt(np.sum(np.abs(H1.mean(axis=0)[band] - H) ** 2) / np.sum(np.abs(H) ** 2))
    assert err < 0.1
    np.testing.assert_allclose(H, H.transpose(0, 2, 1), atol=1e-12 * np.abs(H).max())  # reciprocity


def test_out_of_library_frf_case_loads(tmp_path):
    folder, truth = make_case(tmp_path / "rock", kind="frf", robot="arm3", effects=("rocking_base",), seed=5, small=True)
    case = jflex.gap.load_case(folder)
    assert truth["family"] == "out_of_library" and not truth["effects"][0]["in_library"]
    assert {d.kind for d in case.datasets} == {"frf"} and {d.split for d in case.datasets} == {"train", "validation"}
    assert json.loads((folder / "truth.json").read_text()) == truth
