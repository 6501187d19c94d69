"""Scalarised 3-D algebra for the rigid-body kernels.

A 3-vector is a :class:`V3` of three scalars and a rotation an :class:`M33` of three row
vectors. Each scalar is a Python float when it is known at trace time (a robot closed over by
``jit``: axes, placements, inertias) or a traced JAX scalar otherwise. Two things follow:

* arithmetic on known numbers happens in Python while tracing, and products with a known 0 or 1
  are dropped, so an axis-aligned joint or a zero offset costs nothing in the compiled program;
* under ``vmap`` every remaining scalar becomes one contiguous (N,) array and every operation a
  plain elementwise one, which XLA fuses into long vector loops — no tiny batched matrix
  products, no strided slices (measured in benchmarks/bench_dynamics.py).

When the robot itself is traced (``grad`` with respect to its parameters) the same code runs on
traced scalars and stays exact.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def known(a):
    """A Python float for a value known at trace time, else ``a`` unchanged."""
    if isinstance(a, float):
        return a
    if isinstance(a, (int, np.integer, np.floating)):
        return float(a)
    if isinstance(a, jax.core.Tracer):
        return a
    try:
        return float(a)
    except (TypeError, ValueError):
        return a


def _is(a, v):
    return isinstance(a, float) and a == v


def add(a, b):
    if _is(a, 0.0):
        return b
    if _is(b, 0.0):
        return a
    return a + b


def sub(a, b):
    if _is(b, 0.0):
        return a
    if _is(a, 0.0):
        return -b
    return a - b


def mul(a, b):
    if _is(a, 0.0) or _is(b, 0.0):
        return 0.0
    if _is(a, 1.0):
        return b
    if _is(b, 1.0):
        return a
    if _is(a, -1.0):
        return -b
    if _is(b, -1.0):
        return -a
    return a * b


def sum_(*terms):
    out = 0.0
    for t in terms:
        out = add(out, t)
    return out


class V3:
    """A 3-vector of scalars."""

    __slots__ = ("x", "y", "z")

    def __init__(self, x, y, z):
        self.x, self.y, self.z = x, y, z

    @staticmethod
    def of(a) -> "V3":
        """From a (3,) array (entries known at trace time become floats)."""
        return V3(known(a[0]), known(a[1]), known(a[2]))

    def __iter__(self):
        return iter((self.x, self.y, self.z))

    def __getitem__(self, i):
        return (self.x, self.y, self.z)[i]

    def __add__(self, o):
        return V3(add(self.x, o.x), add(self.y, o.y), add(self.z, o.z))

    def __sub__(self, o):
        return V3(sub(self.x, o.x), sub(self.y, o.y), sub(self.z, o.z))

    def __neg__(self):
        return V3(mul(-1.0, self.x), mul(-1.0, self.y), mul(-1.0, self.z))

    def scale(self, s):
        return V3(mul(self.x, s), mul(self.y, s), mul(self.z, s))

    def array(self):
        return jnp.stack(jnp.broadcast_arrays(*(jnp.asarray(c) for c in self)))


ZERO = V3(0.0, 0.0, 0.0)


def dot(a: V3, b: V3):
    return sum_(mul(a.x, b.x), mul(a.y, b.y), mul(a.z, b.z))


def cross(a: V3, b: V3) -> V3:
    return V3(
        sub(mul(a.y, b.z), mul(a.z, b.y)),
        sub(mul(a.z, b.x), mul(a.x, b.z)),
        sub(mul(a.x, b.y), mul(a.y, b.x)),
    )


class M33:
    """A 3x3 matrix as three row vectors."""

    __slots__ = ("r",)

    def __init__(self, r0: V3, r1: V3, r2: V3):
        self.r = (r0, r1, r2)

    @staticmethod
    def of(A) -> "M33":
        return M33(V3.of(A[0]), V3.of(A[1]), V3.of(A[2]))

    @staticmethod
    def eye() -> "M33":
        return M33(V3(1.0, 0.0, 0.0), V3(0.0, 1.0, 0.0), V3(0.0, 0.0, 1.0))

    @property
    def T(self) -> "M33":
        r = self.r
        return M33(V3(r[0].x, r[1].x, r[2].x), V3(r[0].y, r[1].y, r[2].y), V3(r[0].z, r[1].z, r[2].z))

    def mv(self, v: V3) -> V3:
        return V3(dot(self.r[0], v), dot(self.r[1], v), dot(self.r[2], v))

    def tv(self, v: V3) -> V3:
        """self.T @ v"""
        r = self.r
        return r[0].scale(v.x) + r[1].scale(v.y) + r[2].scale(v.z)

    def mm(self, B: "M33") -> "M33":
        Bt = B.T
        return M33(*(V3(dot(row, Bt.r[0]), dot(row, Bt.r[1]), dot(row, Bt.r[2])) for row in self.r))

    def __add__(self, o):
        return M33(*(a + b for a, b in zip(self.r, o.r)))

    def scale(self, s):
        return M33(*(row.scale(s) for row in self.r))

    def array(self):
        return jnp.stack([row.array() for row in self.r])


def skew(a: V3) -> M33:
    return M33(V3(0.0, mul(-1.0, a.z), a.y), V3(a.z, 0.0, mul(-1.0, a.x)), V3(mul(-1.0, a.y), a.x, 0.0))


def outer(a: V3, b: V3) -> M33:
    return M33(b.scale(a.x), b.scale(a.y), b.scale(a.z))


def rot_axis_angle(axis: V3, c, s) -> M33:
    """Rotation about a unit axis given cos and sin of the angle: c 1 + s [a]x + (1 - c) a a^T."""
    one_c = sub(1.0, c)
    K = skew(axis)
    A = outer(axis, axis)
    rows = []
    for i in range(3):
        e = [1.0 if j == i else 0.0 for j in range(3)]
        rows.append(V3(*(sum_(mul(c, e[j]), mul(s, K.r[i][j]), mul(one_c, A.r[i][j])) for j in range(3))))
    return M33(*rows)


class Inertia:
    """10 inertial parameters as scalars: mass, first moment h = m c, rotational inertia about the
    origin (symmetric, stored as a matrix)."""

    __slots__ = ("m", "h", "I")

    def __init__(self, m, h: V3, I: M33):
        self.m, self.h, self.I = m, h, I

    @staticmethod
    def of(pi) -> "Inertia":
        p = [known(pi[k]) for k in range(10)]
        I = M33(V3(p[4], p[5], p[7]), V3(p[5], p[6], p[8]), V3(p[7], p[8], p[9]))
        return Inertia(p[0], V3(p[1], p[2], p[3]), I)

    def __add__(self, o):
        return Inertia(add(self.m, o.m), self.h + o.h, self.I + o.I)

    def apply(self, w: V3, v: V3):
        """Spatial inertia times motion (w, v) -> momentum (n, f)."""
        return self.I.mv(w) - cross(v, self.h), v.scale(self.m) + cross(w, self.h)

    def to_parent(self, R: M33, p: V3) -> "Inertia":
        """Re-express about the parent frame, this frame sitting at (R, p) in it."""
        h = R.mv(self.h)
        I = R.mm(self.I).mm(R.T)
        hp, pp = dot(h, p), dot(p, p)
        diag = add(mul(2.0, hp), mul(self.m, pp))
        rows = []
        for i in range(3):
            row = []
            for j in range(3):
                d = sum_(
                    diag if i == j else 0.0,
                    mul(-1.0, mul(h[i], p[j])),
                    mul(-1.0, mul(p[i], h[j])),
                    mul(-1.0, mul(self.m, mul(p[i], p[j]))),
                )
                row.append(add(I.r[i][j], d))
            rows.append(V3(*row))
        return Inertia(self.m, h + p.scale(self.m), M33(*rows))


def motion_to_child(R: M33, p: V3, w: V3, v: V3):
    """Express a parent-frame motion (w, v) in the child frame placed at (R, p)."""
    return R.tv(w), R.tv(v + cross(w, p))


def force_to_parent(R: M33, p: V3, n: V3, f: V3):
    """Express a child-frame force (n, f) in the parent frame."""
    fp = R.mv(f)
    return R.mv(n) + cross(p, fp), fp


def cross_motion(w: V3, v: V3, w2: V3, v2: V3):
    return cross(w, w2), cross(w, v2) + cross(v, w2)


def cross_force(w: V3, v: V3, n: V3, f: V3):
    return cross(w, n) + cross(v, f), cross(w, f)


def barrier(*objs):
    """Pass V3/M33/Inertia/scalars through ``lax.optimization_barrier``.

    XLA's loop fusion duplicates cheap elementwise producers into every consumer; on one long
    elementwise graph (the whole tree) that recomputation grows without bound (the MJX pitfall
    in DESIGN.md). A barrier per body keeps fusions to one body's worth of work."""
    flat, rebuild = [], []

    def put(x):
        if isinstance(x, V3):
            idx = [put(c) for c in x]
            return ("v", idx)
        if isinstance(x, M33):
            return ("m", [put(r) for r in x.r])
        if isinstance(x, Inertia):
            return ("i", [put(x.m), put(x.h), put(x.I)])
        if isinstance(x, float) or x is None:
            return ("c", x)
        flat.append(x)
        return ("t", len(flat) - 1)

    def get(tag, vals):
        kind, d = tag
        if kind == "v":
            return V3(*(get(t, vals) for t in d))
        if kind == "m":
            return M33(*(get(t, vals) for t in d))
        if kind == "i":
            return Inertia(*(get(t, vals) for t in d))
        if kind == "c":
            return d
        return vals[d]

    tags = [put(o) for o in objs]
    if not flat:
        return objs
    vals = jax.lax.optimization_barrier(tuple(flat))
    return tuple(get(t, vals) for t in tags)


def stack(scalars, dtype):
    """Stack scalars (floats or traced) into an array of ``dtype``."""
    arrs = [jnp.asarray(s, dtype=dtype) for s in scalars]
    return jnp.stack(jnp.broadcast_arrays(*arrs))
