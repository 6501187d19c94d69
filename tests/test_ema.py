"""EMA helpers against closed forms: modal parameters of known M, C, K (scipy eigensolver),
discrete-time FRFs (scipy.signal), a hand-written UFF 58 file."""

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

import jflex
from jflex import identify as idf

M = np.diag([2.0, 1.5, 1.0])
K = np.array([[3000.0, -1200.0, 0.0], [-1200.0, 2500.0, -800.0], [0.0, -800.0, 900.0]]) * 10
C = 0.0005 * K + 0.4 * M


def _reference_modes():
    n = 3
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    lam, V = scipy.linalg.eig(A)
    keep = lam.imag > 0
    lam, V = lam[keep], V[:n, keep]
    o = np.argsort(np.abs(lam))
    return np.abs(lam[o]) / (2 * np.pi), -lam[o].real / np.abs(lam[o]), V[:, o]


def _frf(freq):
    w = 2 * np.pi * freq
    return np.stack([np.linalg.inv(K - wi**2 * M + 1j * wi * C)[:, 0] for wi in w])


def test_lscf_recovers_poles_and_residues_give_shapes():
    f_ref, z_ref, V = _reference_modes()
    freq = np.linspace(0.5, 40, 800)
    H = _frf(freq)
    res = idf.lscf(freq, H, orders=range(6, 31, 2))
    f, z = idf.stable_modes(res, min_count=4)
    assert f.shape == (3,)
    assert np.allclose(f, f_ref, rtol=1e-5) and np.allclose(z, z_ref, rtol=1e-3)
    shapes = idf.modal_residues(freq, H, f, z)
    assert np.all(np.diag(np.asarray(jflex.mac(shapes, V))) > 0.999)
    # Noisy: 1 % complex noise.
    rng = np.random.default_rng(0)
    Hn = H * (1 + 0.01 * (rng.normal(size=H.shape) + 1j * rng.normal(size=H.shape)))
    f2, z2 = idf.stable_modes(idf.lscf(freq, Hn, orders=range(6, 41, 2)), min_count=3)
    assert len(f2) >= 3
    k = [np.argmin(np.abs(f2 - fr)) for fr in f_ref]
    assert np.allclose(f2[k], f_ref, rtol=5e-3) and np.allclose(z2[k], z_ref, rtol=0.1)


def test_peak_picking_half_power():
    f_ref, z_ref, _ = _reference_modes()
    freq = np.linspace(0.5, 40, 8000)
    f, z, _ = idf.peak_picking(freq, _frf(freq), n_modes=3, prominence=1e-3)
    assert np.allclose(f, f_ref, rtol=5e-3)
    assert np.allclose(z, z_ref, rtol=0.15)  # half-power bandwidth is an O(zeta^2) approximation


def test_h1_h2_and_coherence_from_time_data():
    # A damped SDOF discretised exactly (zoh): its discrete FRF (scipy.signal.freqz) is the reference.
    fs, wn, zeta, m = 200.0, 2 * np.pi * 12.0, 0.03, 1.0
    sysd = scipy.signal.cont2discrete(([1 / m], [1, 2 * zeta * wn, wn**2]), 1 / fs, method="zoh")
    b, a = np.squeeze(sysd[0]), sysd[1]
    rng = np.random.default_rng(1)
    x = rng.normal(size=2**16)
    y = scipy.signal.lfilter(b, a, x)
    est = idf.frf_estimate(x, y, fs, nperseg=1024, window="hann")
    _, Href = scipy.signal.freqz(b, a, worN=est.freq, fs=fs)
    band = (est.freq > 2) & (est.freq < 60)
    err = np.abs(est.H[band, 0] / Href[band] - 1)
    assert np.median(err) < 0.02 and est.coherence[band].min() > 0.9
    # Output noise: H1 stays unbiased, H2 is biased upward where the response is weak.
    yn = y + rng.normal(size=y.shape) * 0.1 * np.std(y)
    h1 = idf.frf_estimate(x, yn, fs, nperseg=1024)
    h2 = idf.frf_estimate(x, yn, fs, nperseg=1024, estimator="H2")
    hi = (est.freq > 30) & (est.freq < 40)
    assert np.median(np.abs(h1.H[hi, 0] / Href[hi])) == pytest.approx(1.0, abs=0.05)
    assert np.median(np.abs(h2.H[hi, 0] / Href[hi])) > 2.0
    assert h1.coherence[hi].mean() < 0.5


_UFF = """    -1
    58
FRF point 3 +Z / 3 +Z
NONE
01-JAN-26 12:00:00
NONE
NONE
    4         1    1         0 NONE               3   3 NONE               3   3
         6         3         1  1.00000E+00  5.00000E-01  0.00000E+00
        18    0    0    0 Frequency            Hz
         8    0    0    0 Displacement         m
        13    0    0    0 Force                N
         0    0    0    0 NONE                 NONE
  1.000000000000E-03 -2.000000000000E-03  3.000000000000E-03  4.000000000000E-03
 -5.000000000000E-03  6.000000000000E-03
    -1
"""


def test_read_uff58_fixture_and_round_trip(tmp_path):
    p = tmp_path / "frf.uff"
    p.write_text("    -1\n   151\nheader\n    -1\n" + _UFF)
    (d,) = idf.read_uff58(p)
    assert d.function_type == 4 and d.response == (3, 3) and d.reference == (3, 3)
    assert np.allclose(d.x, [1.0, 1.5, 2.0])
    assert np.allclose(d.data, [1e-3 - 2e-3j, 3e-3 + 4e-3j, -5e-3 + 6e-3j])
    assert d.units == ("Hz", "m", "N")
    freq = np.linspace(1, 50, 50)
    H = _frf(freq)[:, 1]
    q = tmp_path / "out.uff"
    idf.write_uff58(q, freq, H, response=(21, -2), reference=(21, 3))
    (e,) = idf.read_uff58(q)
    assert np.allclose(e.data, H, rtol=1e-11) and e.response == (21, -2) and np.allclose(e.x, freq)


def test_read_uff58_bad_files(tmp_path):
    p = tmp_path / "bad.uff"
    p.write_text(_UFF.replace("         6         3         1", "         6         4         1"))
    with pytest.raises(jflex.DataError, match=r"bad\.uff.*announces 4 points"):
        idf.read_uff58(p)
    p.write_text("    -1\n    58b     2         1\n    -1\n")
    with pytest.raises(jflex.DataError, match="binary"):
        idf.read_uff58(p)
    p.write_text("hello\n")
    with pytest.raises(jflex.DataError, match="no dataset 58"):
        idf.read_uff58(p)
