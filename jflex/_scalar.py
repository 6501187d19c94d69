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


def signed_sum(pairs):
    """sum of a_k b_k with products by a known -1 turned into subtractions (each negation would
    otherwise be one more pass over the batch) and positive terms first."""
    pos, neg = [], []
    for a, b in pairs:
        if _is(a, -1.0) or _is(b, -1.0):
            neg.append(b if _is(a, -1.0) else a)
        else:
            t = mul(a, b)
            if not _is(t, 0.0):
                pos.append(t)
    out = sum_(*pos)
    for t in neg:
        out = sub(out, t)
    return out


def dot(a: V3, b: V3):
    return signed_sum(((a.x, b.x), (a.y, b.y), (a.z, b.z)))


def _diff(a1, b1, a2, b2):
    """a1 b1 - a2 b2, with a lone negative term folded into its known factor (no negation pass)."""
    t1 = mul(a1, b1)
    if _is(t1, 0.0):
        if isinstance(a2, float):
            return mul(-a2, b2)
        if isinstance(b2, float):
            return mul(a2, -b2)
    return sub(t1, mul(a2, b2))


def cross(a: V3, b: V3) -> V3:
    return V3(_diff(a.y, b.z, a.z, b.y), _diff(a.z, b.x, a.x, b.z), _diff(a.x, b.y, a.y, b.x))


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
    for k in range(3):  # about a coordinate axis: the plain 2x2 rotation, nothing to fold away
        i, j = (k + 1) % 3, (k + 2) % 3
        if _is(axis[k], 1.0) or _is(axis[k], -1.0):
            if _is(axis[i], 0.0) and _is(axis[j], 0.0):
                sn = s if axis[k] == 1.0 else -s
                e = [[None] * 3 for _ in range(3)]
                e[k][k], e[i][k], e[j][k], e[k][i], e[k][j] = 1.0, 0.0, 0.0, 0.0, 0.0
                e[i][i], e[j][j], e[i][j], e[j][i] = c, c, -sn, sn
                return M33(*(V3(*row) for row in e))
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
        """Re-express about the parent frame, this frame sitting at (R, p) in it.

        Only the six distinct entries of the symmetric inertia are formed, and the parallel-axis
        term is written with u = R h + (m/2) p as 2 (u.p) 1 - (u p^T + p u^T): about half the
        operations of the textbook form, which matters in CRBA's composite pass."""
        h = R.mv(self.h)
        S = _sym_rotate(R, self.I)
        u = h + p.scale(mul(0.5, self.m))
        t = [mul(u[k], p[k]) for k in range(3)]
        out = {}
        for i, j in _UPPER:
            if i == j:  # S_ii + 2 (u.p - u_i p_i)
                out[i, i] = add(S[i, i], mul(2.0, sum_(*(t[k] for k in range(3) if k != i))))
            else:
                out[i, j] = sub(S[i, j], add(mul(u[i], p[j]), mul(p[i], u[j])))
        return Inertia(self.m, h + p.scale(self.m), _sym_matrix(out))

    def rotated_z(self, c, s) -> "Inertia":
        """The same body seen from a frame turned by -angle about z (R I R^T with R = Rz(angle)),
        given cos and sin: the 2x2 block by the double-angle form, a dozen operations."""
        I = self.I
        xx, xy, yy, xz, yz, zz = I.r[0].x, I.r[0].y, I.r[1].y, I.r[0].z, I.r[1].z, I.r[2].z
        cc, ss, cs = mul(c, c), mul(s, s), mul(c, s)
        nxx = sub(add(mul(cc, xx), mul(ss, yy)), mul(mul(2.0, cs), xy))
        nyy = sub(add(xx, yy), nxx)
        nxy = add(mul(cs, sub(xx, yy)), mul(sub(cc, ss), xy))
        nxz = sub(mul(c, xz), mul(s, yz))
        nyz = add(mul(s, xz), mul(c, yz))
        h = self.h
        nh = V3(sub(mul(c, h.x), mul(s, h.y)), add(mul(s, h.x), mul(c, h.y)), h.z)
        return Inertia(self.m, nh, _sym_matrix({(0, 0): nxx, (0, 1): nxy, (1, 1): nyy, (0, 2): nxz, (1, 2): nyz, (2, 2): zz}))


_UPPER = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))


def _sym_matrix(e) -> M33:
    return M33(V3(e[0, 0], e[0, 1], e[0, 2]), V3(e[0, 1], e[1, 1], e[1, 2]), V3(e[0, 2], e[1, 2], e[2, 2]))


def _sym_rotate(R: M33, I: M33) -> dict:
    """Upper triangle of R I R^T for symmetric I (six entries instead of nine)."""
    RI = [V3(*(dot(R.r[i], I.T.r[k]) for k in range(3))) for i in range(3)]
    return {(i, j): dot(RI[i], R.r[j]) for i, j in _UPPER}


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


def barrier(*objs, fence=None):
    """Pass V3/M33/Inertia/scalars through ``lax.optimization_barrier``.

    XLA's loop fusion duplicates cheap elementwise producers into every consumer; on one long
    elementwise graph (the whole tree) that recomputation grows without bound (MuJoCo MJX's
    kernels meet the same; benchmarks/bench_dynamics.py measures it). A barrier per body keeps
    fusions to one body's worth of work.

    ``fence`` (an unbatched boolean, false at run time; see ``_tree.consts``): pass the values
    through ``lax.cond(fence, NaN, identity)`` instead. XLA:CPU removes optimization barriers
    before its fusion pass; a conditional stays a boundary, so the values are computed once. With
    the robot traced (passed to ``jit``) this cut the Panda's ABA from 31k to 9k multiplies in the
    compiled program and its compile time 2.5x."""
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
    if fence is None:
        vals = jax.lax.optimization_barrier(tuple(flat))
    else:
        vals = jax.lax.cond(fence, lambda v: tuple(jnp.full_like(x, jnp.nan) for x in v), lambda v: v, tuple(flat))
    return tuple(get(t, vals) for t in tags)


def stack(scalars, dtype):
    """Stack scalars (floats or traced) into an array of ``dtype``."""
    arrs = [jnp.asarray(s, dtype=dtype) for s in scalars]
    return jnp.stack(jnp.broadcast_arrays(*arrs))
