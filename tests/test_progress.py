"""Progress on stderr: the same results with it on or off; tqdm redraws on a terminal, plain lines
(no carriage returns, a few per loop, one per stage) in a log, a pipe or a notebook; stage lines
that name their stages."""

import io
import sys

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jflex
from jflex import identify as idf
from jflex._progress import stages


class _Terminal(io.StringIO):
    """A stderr that says it is a terminal, to see what a person would see."""

    def isatty(self):
        return True


class _Log(io.StringIO):
    def isatty(self):
        return False


def _run_with(stream, monkeypatch, fn):
    monkeypatch.setattr(sys, "stderr", stream)
    return fn(), stream.getvalue()


def _sweep(progress):
    q = np.linspace(0.0, 1.0, 23)[:, None] * np.ones((1, 3))
    return jflex.sweep(lambda x: {"s": jnp.sin(x) * 2.0, "n": jnp.sum(x**2)}, q, chunk_size=5,
                       progress=progress, label="sines")


@pytest.mark.parametrize("stream", [_Terminal, _Log])
def test_sweep_same_result_with_progress_on_and_off(stream, monkeypatch):
    on, err_on = _run_with(stream(), monkeypatch, lambda: _sweep(True))
    off, err_off = _run_with(stream(), monkeypatch, lambda: _sweep(False))
    for k in on:
        np.testing.assert_array_equal(on[k], off[k])
    assert err_off == ""
    if stream is _Terminal:  # a bar named by its label that reached the end
        assert "sines" in err_on and "23/23" in err_on
    else:  # not a terminal: plain lines, no '\r' redraws: the start and the end (a quick loop)
        assert "\r" not in err_on
        lines = err_on.splitlines()
        assert lines[0] == "sines: 0/23 it" and lines[-1].startswith("sines: 23/23 it done in "), lines
        assert len(lines) <= 2 + 1  # at most one line every few seconds in between


def test_frf_sweep_writes_plain_lines_in_a_log(monkeypatch):
    robot = jflex.from_dh([[0, 0, 0, 0], [0, 0.5, 0, 0]],
                          inertias=[{"mass": 3.0, "com": [0.25, 0, 0], "inertia": [0.01, 0, 0.06, 0, 0, 0.06]},
                                    {"mass": 1.5, "com": [0.2, 0, 0], "inertia": [0.005, 0, 0.03, 0, 0, 0.03]}])
    model = jflex.Model(robot, [jflex.effects.FlexibleJoints([2e4, 1e4], [5.0, 3.0], rotor_inertia=[1e-3] * 2,
                                                             gear_ratio=[50.0] * 2)])
    Q = np.array([[0.1, 0.2], [0.3, -0.4], [0.0, 1.0]])
    w = np.linspace(10.0, 500.0, 7)
    kw = dict(hold="actuated", chunk_size=2, block_size=1)
    on, err = _run_with(_Log(), monkeypatch, lambda: jflex.frf_sweep(model, Q, w, progress=True, **kw))
    assert "\r" not in err and "3/3 posture done in" in err, err
    on_tty, err_tty = _run_with(_Terminal(), monkeypatch, lambda: jflex.frf_sweep(model, Q, w, progress=True, **kw))
    assert "frf_sweep" in err_tty and "3/3" in err_tty
    np.testing.assert_array_equal(on, on_tty)


class _Sine(eqx.Module):
    omega: jnp.ndarray
    amp: jnp.ndarray


class _SineData(idf.AbstractData):
    t: jnp.ndarray
    y: jnp.ndarray

    def residuals(self, m):
        return {"y": (m.amp * jnp.sin(m.omega * self.t) - self.y) / jnp.sqrt(self.t.size)}

    def nrmse(self, m):
        return {"sine:y": jnp.sqrt(jnp.sum(self.residuals(m)["y"] ** 2))}


def test_fit_same_result_with_progress_on_and_off(monkeypatch):
    t = jnp.linspace(0, 3, 60)
    data = _SineData(t, 1.3 * jnp.sin(2.0 * t))
    spec = idf.ParameterSpec([idf.Free("omega", lambda m: m.omega), idf.Free("amp", lambda m: m.amp)])
    start = _Sine(jnp.asarray(1.8), jnp.asarray(1.0))
    runs = {}
    for name, stream, progress in (("off", _Terminal(), False), ("log", _Log(), True), ("tty", _Terminal(), True)):
        runs[name] = _run_with(stream, monkeypatch, lambda: idf.fit(start, spec, data, progress=progress, max_steps=40))
    assert runs["off"][1] == "" and "\r" not in runs["log"][1]
    assert runs["log"][1].startswith("fit: 0/40 step\n") and " done in " in runs["log"][1], runs["log"][1]
    assert "fit" in runs["tty"][1] and "cost" in runs["tty"][1]
    for name in ("log", "tty"):
        assert runs[name][0].values == runs["off"][0].values
        assert runs[name][0].history == runs["off"][0].history
    assert abs(float(runs["off"][0].values["omega"]) - 2.0) < 1e-6  # the fit itself worked


def test_stage_line_names_each_stage_on_a_terminal_only(monkeypatch):
    def job(say):
        say("nominal fit")
        say("  coulomb_friction@j1: shrink 80 %")  # a detail: kept, not a stage
        say("selecting")
        return 7

    def run(progress):
        with stages("diagnose", progress) as say:
            return job(say)

    out, err = _run_with(_Terminal(), monkeypatch, lambda: run(True))
    assert out == 7
    assert "diagnose: nominal fit (" in err and "diagnose: selecting (" in err  # finished stages, timed
    assert "coulomb_friction@j1: shrink 80 %" in err and "coulomb_friction@j1: shrink 80 % (" not in err
    log = _run_with(_Log(), monkeypatch, lambda: run(True))[1]
    assert "\r" not in log
    assert log.splitlines()[:3] == ["diagnose: nominal fit", "diagnose:   coulomb_friction@j1: shrink 80 %",
                                    "diagnose: selecting"] and log.splitlines()[3].startswith("diagnose: done ("), log
    assert _run_with(_Log(), monkeypatch, lambda: run(False))[1] == ""
    assert _run_with(_Terminal(), monkeypatch, lambda: run(False))[1] == ""
    seen = []
    assert _run_with(_Terminal(), monkeypatch, lambda: run(seen.append))[1] == ""  # a callable gets the lines
    assert seen == ["nominal fit", "  coulomb_friction@j1: shrink 80 %", "selecting"]


def test_a_long_loop_in_a_log_writes_a_line_every_few_seconds(monkeypatch):
    # a clock that advances 1 s per step: 23 steps give a line at 5, 10, 15 and 20 s, not 23
    from jflex import _progress

    clock = iter(range(1000))
    monkeypatch.setattr(_progress.time, "perf_counter", lambda: float(next(clock)))
    _, err = _run_with(_Log(), monkeypatch, lambda: _run_bar(_progress, 23))
    lines = err.splitlines()
    assert lines[0] == "loop: 0/23 it" and lines[-1].startswith("loop: 23/23 it done in")
    middle = lines[1:-1]
    assert 3 <= len(middle) <= 5 and all(line.startswith("loop: ") and "(" in line for line in middle), lines


def _run_bar(_progress, n):
    with _progress.bar(n, "loop", True) as b:
        for _ in range(n):
            b.update(1)


def test_a_bar_takes_a_new_label_on_a_terminal_and_in_a_log(monkeypatch):
    # a bench names the case it is on: in a log (CI, | tee) the plain bar raised AttributeError
    from jflex import _progress

    def run():
        with _progress.bar(2, "bench", True, unit="case") as b:
            for name in ("case-a", "case-b"):
                b.set_description_str(f"bench {name}")
                b.update()

    for stream in (_Log(), _Terminal()):
        _, err = _run_with(stream, monkeypatch, run)
        assert "bench case-b" in err
