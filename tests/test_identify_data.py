"""Bad input: every data problem raises jflex.DataError naming the file and the field."""

import numpy as np
import pytest

import jflex
from jflex import identify as idf


def _save(tmp_path, name="run.npz", **arrays):
    p = tmp_path / name
    np.savez(p, **arrays)
    return p


def _good(n=50):
    t = np.arange(n) * 0.01
    return dict(t=t, q=np.zeros((n, 3)), tau=np.ones((n, 3)))


def test_load_npz_good(tmp_path):
    d = idf.load_npz(_save(tmp_path, **_good()), ["q", "tau"], uniform=True)
    assert d["q"].shape == (50, 3)


@pytest.mark.parametrize(
    "mutate, kwargs, pattern",
    [
        (lambda d: d["q"].__setitem__((7, 1), np.nan), {}, r"run\.npz: field 'q': contains 1 NaN/inf value\(s\), the first at index \(7, 1\)"),
        (lambda d: d.__setitem__("tau", np.ones((49, 3))), {}, r"run\.npz: field 'tau': has 49 samples .* 't' has 50"),
        (lambda d: d["t"].__setitem__(10, d["t"][9] - 1e-3), {}, r"run\.npz: field 't': time must be strictly increasing, but t\[10\]"),
        (lambda d: d["t"].__setitem__(slice(25, None), d["t"][25:] + 0.003), {"uniform": True}, r"run\.npz: field 't': uniform sampling is required"),
        (lambda d: d.pop("tau"), {}, r"run\.npz: missing field\(s\) \['tau'\]"),
        (lambda d: d.__setitem__("q", np.array(["a"] * 50)), {}, r"run\.npz: field 'q': expected numbers"),
    ],
)
def test_load_npz_bad(tmp_path, mutate, kwargs, pattern):
    d = _good()
    mutate(d)
    with pytest.raises(jflex.DataError, match=pattern):
        idf.load_npz(_save(tmp_path, **d), ["q", "tau"], **kwargs)


def test_non_uniform_allowed_when_not_required(tmp_path):
    d = _good()
    d["t"][25:] += 0.003
    idf.load_npz(_save(tmp_path, **d), ["q", "tau"])


def test_missing_and_corrupt_files(tmp_path):
    with pytest.raises(jflex.DataError, match="nothere.npz: data file not found"):
        idf.load_npz(tmp_path / "nothere.npz", ["q"])
    p = tmp_path / "junk.npz"
    p.write_text("not a zip")
    with pytest.raises(jflex.DataError, match="junk.npz: not a readable NPZ"):
        idf.load_npz(p, ["q"])


def test_residual_builders_reject_bad_data():
    q = np.zeros((20, 2))
    with pytest.raises(jflex.DataError, match=r"exp1\.npz: field 'tau': has 19 samples"):
        idf.TorqueData(q, q, q, np.zeros((19, 2)), source="exp1.npz")
    with pytest.raises(jflex.DataError, match=r"field 'qd': contains 1 NaN"):
        idf.TorqueData(q, np.pad([[np.nan, 0.0]], ((0, 19), (0, 0))), q, q)
    with pytest.raises(jflex.DataError, match=r"modal\.yaml: field 'frequency': expected shape \(2, m\)"):
        idf.ModalData(np.zeros((2, 3)), np.ones((3, 3)), np.ones((3, 3)), source="modal.yaml")
    with pytest.raises(jflex.DataError, match=r"field 'frequency': natural frequencies must be > 0"):
        idf.ModalData(np.zeros((1, 3)), [[-1.0, 2.0]], [[0.01, 0.01]])
    with pytest.raises(jflex.DataError, match=r"hammer\.npz: field 'omega': expected strictly increasing"):
        idf.FRFData(np.zeros((1, 3)), [2.0, 1.0], np.ones((1, 2, 3, 3)), source="hammer.npz")
    with pytest.raises(jflex.DataError, match=r"field 'H': expected \(P, F, a, b\)"):
        idf.FRFData(np.zeros((2, 3)), [1.0, 2.0], np.ones((1, 2, 3, 3)))


def test_signal_processing_requires_finite_data():
    with pytest.raises(jflex.DataError, match="field 'q': contains"):
        idf.spectral_derivatives(np.array([[0.0], [np.inf], [1.0], [2.0]]), 0.01)
