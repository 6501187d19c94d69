"""A resumed sweep does not return stale chunks when the function reads a value from a global
object's attribute (``CFG.gain``): the chunk fingerprint covers the object's attributes."""

from __future__ import annotations

import numpy as np
import pytest

import jflex


class _Cfg:
    def __init__(self, gain):
        self.gain = gain


CFG = _Cfg(2.0)


def _scaled(x):
    return CFG.gain * x


def test_changed_global_attribute_is_not_resumed_stale(tmp_path):
    xs = np.arange(6.0)
    out = np.asarray(jflex.sweep(_scaled, xs, out_dir=tmp_path, chunk_size=3))
    np.testing.assert_allclose(out, 2.0 * xs)
    CFG.gain = 5.0
    try:
        try:
            again = np.asarray(jflex.sweep(_scaled, xs, out_dir=tmp_path, chunk_size=3))
        except jflex.JFlexError as exc:  # refusing to resume a folder of another computation is sound too
            assert "function" in str(exc)
            return
        np.testing.assert_allclose(again, 5.0 * xs)
    finally:
        CFG.gain = 2.0


def test_fingerprint_sees_object_attributes():
    from jflex._fingerprint import fingerprint

    assert fingerprint(_Cfg(1.0)) != fingerprint(_Cfg(2.0))
    assert fingerprint(_Cfg(1.0)) == fingerprint(_Cfg(1.0))
