"""sweep resume never returns stale results (issue 15 item 3): chunks carry a fingerprint of the
inputs, the function (with what it closes over, e.g. a robot), the chunk size and a key; a folder
written by another sweep or a damaged chunk is refused by name, nothing in it reused."""

import os

import jax.numpy as jnp
import numpy as np
import pytest

import jflex

N = 1000


def pendulum(m):
    """One revolute joint about +y, point mass m at x = 0.5 m: gravity torque -m g l cos(q)."""
    return jflex.make_robot(
        joint_names=["j"], link_names=["bob"], parents=[-1], joint_types=["revolute"],
        placement_R=np.eye(3)[None], placement_p=np.zeros((1, 3)), axis=[[0, 1.0, 0]],
        inertia=[[m, 0.5 * m, 0, 0, 0, 0, 0.25 * m, 0, 0, 0.25 * m]], gravity=(0, 0, -9.81),
    )


def torque_of(robot):
    return lambda q: jflex.gravity(robot, q)


def expected(m, q):
    return -m * 9.81 * 0.5 * np.cos(q)


class Stop(Exception):
    pass


def stop_after(k):
    seen = []

    def cb(start, stop, out):
        seen.append(start)
        if len(seen) == k:
            raise Stop

    return cb


@pytest.fixture
def q():
    return np.random.default_rng(1).uniform(-3, 3, (N, 1))


def run(fn, q, folder, chunk, **kw):
    return jflex.sweep(fn, q, chunk_size=chunk, out_dir=folder, progress=False, **kw)


def test_interrupted_sweep_resumes_with_the_right_values(q, tmp_path):
    fn = torque_of(pendulum(2.0))
    with pytest.raises(Stop):
        run(fn, q, tmp_path, 200, on_chunk=stop_after(2))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["chunk_000000000.npz", "chunk_000000200.npz", "sweep.json"]
    loaded = []
    out = run(fn, q, tmp_path, 200, on_chunk=lambda a, b, o: loaded.append(a))
    assert out.shape == (N, 1) and loaded == [0, 200, 400, 600, 800]
    np.testing.assert_allclose(out, expected(2.0, q), rtol=1e-12, atol=1e-12)
    # the same sweep from a fresh closure (same code, same robot) reuses every chunk
    out2 = run(torque_of(pendulum(2.0)), q, tmp_path, 200)
    np.testing.assert_array_equal(out2, out)
    assert not [p for p in tmp_path.iterdir() if "tmp" in p.name]


@pytest.mark.parametrize("change", ["chunk_size", "function", "robot", "inputs", "key"])
def test_a_changed_sweep_is_refused_then_recomputed(q, tmp_path, change):
    """Between two runs in one folder: chunk size 200 -> 300, another function, the robot's mass
    2 -> 3 kg (same code), other inputs, another key. The second run refuses the folder by name;
    after clearing it, the result is complete and right (no stale rows)."""
    with pytest.raises(Stop):
        run(torque_of(pendulum(2.0)), q, tmp_path, 200, on_chunk=stop_after(3), key="a")
    m, fn, q2, chunk, key = 2.0, torque_of(pendulum(2.0)), q, 200, "a"
    if change == "chunk_size":
        chunk = 300
    elif change == "function":
        fn = lambda x: 2.0 * jflex.gravity(pendulum(2.0), x) / 2.0 + 0.0 * x  # noqa: E731
    elif change == "robot":
        m, fn = 3.0, torque_of(pendulum(3.0))
    elif change == "inputs":
        q2 = q + 0.01
    else:
        key = "b"
    with pytest.raises(jflex.DataError) as e:
        run(fn, q2, tmp_path, chunk, key=key)
    msg = str(e.value)
    assert str(tmp_path) in msg and "clear the folder" in msg and "nothing in it was reused" in msg
    assert {"chunk_size": "chunk_size 200 -> 300", "function": "function", "robot": "robot",
            "inputs": "inputs changed", "key": "key 'a' -> 'b'"}[change] in msg
    for p in tmp_path.iterdir():
        p.unlink()
    out = run(fn, q2, tmp_path, chunk, key=key)
    assert out.shape == (N, 1)
    np.testing.assert_allclose(out, expected(m, q2), rtol=1e-12, atol=1e-12)


def test_damaged_or_foreign_chunk_is_refused_by_name(q, tmp_path):
    fn = torque_of(pendulum(2.0))
    run(fn, q, tmp_path, 250)
    chunk = tmp_path / "chunk_000000500.npz"
    data = chunk.read_bytes()
    chunk.write_bytes(data[: len(data) // 2])  # a chunk cut short (killed writer, full disk)
    with pytest.raises(jflex.DataError, match=r"chunk_000000500\.npz is damaged \(BadZipFile"):
        run(fn, q, tmp_path, 250)
    # a chunk copied in from another sweep (same layout, other values) is refused, not reused
    other = tmp_path.parent / (tmp_path.name + "_other")
    run(fn, q + 1.0, other, 250)
    chunk.write_bytes((other / "chunk_000000500.npz").read_bytes())
    with pytest.raises(jflex.DataError, match=r"chunk_000000500\.npz was written by a different sweep"):
        run(fn, q, tmp_path, 250)


def test_folder_without_fingerprints_is_refused(q, tmp_path):
    np.savez(tmp_path / "chunk_000000000.npz", leaf0=np.zeros((200, 1)))
    with pytest.raises(jflex.DataError, match=r"chunk_000000000\.npz has no fingerprint"):
        run(torque_of(pendulum(2.0)), q, tmp_path, 200)


def test_fingerprint_sees_closures_partials_and_arrays():
    import functools

    from jflex._fingerprint import fingerprint

    a, b = jnp.arange(3.0), jnp.arange(3.0) + 1

    def f(x, w):
        return x * w

    assert fingerprint(functools.partial(f, w=a)) == fingerprint(functools.partial(f, w=jnp.arange(3.0)))
    assert fingerprint(functools.partial(f, w=a)) != fingerprint(functools.partial(f, w=b))
    assert fingerprint(lambda x: x + 1) != fingerprint(lambda x: x + 2)
    assert fingerprint(pendulum(2.0)) != fingerprint(pendulum(2.0 + 1e-12))
    assert fingerprint(np.zeros(3, np.float32)) != fingerprint(np.zeros(3))
