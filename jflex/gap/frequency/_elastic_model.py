"""The frequency side of the gap diagnosis: a :class:`jflex.Model` of elastic sites at each measured
posture, evaluated fast for the many parameter values of a fit.

The motors are held (perfect position control, as the thesis "Posture Dependent Dynamics in Robotic Machining" assumes), so the model's free
coordinates are its *elastic* ones: the link side of each flexible joint and the virtual joints
that candidates insert into the kinematic tree (:class:`Site`):

- ``orth`` at joint j (orthogonal compliance): two virtual revolute joints at joint j's origin,
  about the two axes perpendicular to its rotation axis (a bearing's tilt);
- ``link`` of link i (link flexibility): two virtual bending hinges at a fraction ``frac`` of link
  i, about the axes perpendicular to the link (its first bending mode, lumped);
- ``joint`` at joint j: a joint the nominal model holds rigid, or a flexible joint's link side.

Each site carries a :class:`jflex.effects.Spring` (a virtual pair may couple its two springs: a full
symmetric positive-definite 2x2 stiffness ``[[k_a, r sqrt(k_a k_b)], [r sqrt(k_a k_b), k_b]]``,
``r = tanh(x_r)``, as the principal axes need not be the ones :func:`_perp` picks) and a damping law
of :mod:`jflex.effects` (:class:`~jflex.effects.StructuralDamping` on the site's stiffness), and the
tool a :class:`jflex.effects.Payload` when the structure has one. :meth:`FrequencyModel.model` is
that :class:`jflex.Model`; its :func:`jflex.linear.frf` with the rigid joints held is what
:meth:`FrequencyModel.frf` returns (checked in the tests). The fit evaluates it without
re-tracing the model for every parameter value: with ``x`` the elastic coordinates,

$$ D(\\omega) = K_g - \\omega^2 M + \\operatorname{diag}_s\\big(k_s + c_s\\,\\psi_s(\\omega)\\big)
   + \\text{couplings}, \\qquad H = J D^{-1} J^T, $$

``M`` and ``K_g`` the linearisation of the rigid augmented robot, other joints held (with the
payload's share, which is linear in its 10 inertial parameters: a rigid body of mass, centre of
mass and rotational inertia, :func:`payload_inertia`), ``J`` the tool Jacobian, and ``psi_s`` the damping
law's own complex modulus with unit loss (:func:`jflex.effects.complex_modulus` less 1: ``i w`` for
Kelvin-Voigt, ``i`` for hysteretic, ``(i w)^alpha`` for fractional damping). ``c_s = k_s theta_s``
is the loss stiffness, ``theta_s`` the law's loss leaf (``k_e``, ``eta``), in which every law of
:mod:`jflex.effects` is linear: a law defined there is evaluated here without a line of its own.
"""

from __future__ import annotations

import dataclasses
import functools

import jax.numpy as jnp
import numpy as np

from ..._dynamics import crba, jacobian
from ..._model import Model, gravity_stiffness
from ..._spatial import inertia_matrix3, params_to_com, skew
from ...effects import Payload, Spring, StructuralDamping
from ._laws import frequency_dependent, unit_loss, with_loss
from ._payload import PAYLOAD_COM_BOX, payload_inertia
from ._sites import augment


@dataclasses.dataclass
class PostureMats:
    M: np.ndarray
    Kg: np.ndarray
    J: np.ndarray
    dM: np.ndarray | None  # (S, S, 10): M's derivative in the payload's 10 inertial parameters
    dKg: np.ndarray | None  # (S, S, 10): K_g's
    # derived, law-independent arrays a fit asks for again and again (per frequency grid): see
    # FrequencyModel._grid; and whether every matrix is exactly symmetric (then D is too, and
    # D^T's solve is D's)
    derived: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)

    def symmetric(self) -> bool:
        s = self.derived.get("sym")
        if s is None:
            s = self.derived["sym"] = bool(all(a is None or np.array_equal(a, a.T) for a in (self.M, self.Kg, self.dM, self.dKg)))
        return s


@dataclasses.dataclass(frozen=True, eq=False)
class Structure:
    """Elastic sites and their laws, plus an optional tool payload: ``payload`` its number of
    parameters (0: none; 1, 4 or 10 of :data:`PAYLOAD_NAMES`: see :func:`payload_inertia`; ``True``
    is 1, a point mass at the tool)."""

    springs: tuple
    payload: int = 0

    def pairs(self) -> list:
        """``[(a, b)]`` site indices of the coupled virtual pairs (``b`` the coupled axis-1 site)."""
        out = []
        for b, s in enumerate(self.springs):
            if s.coupled:
                a = next(i for i, t in enumerate(self.springs) if (t.kind, t.where, t.axis) == (s.kind, s.where, 0))
                out.append((a, b))
        return out

    def n_params(self) -> int:
        return 2 * len(self.springs) + int(self.payload) + len(self.pairs())


def _quiet(fn):
    # trial parameters of a fit can overflow or meet a singular matrix; those show up as NaN/inf
    # residuals (handled by the callers), not as warnings on the console
    @functools.wraps(fn)
    def wrapped(*a, **k):
        with np.errstate(all="ignore"):
            return fn(*a, **k)

    return wrapped


def _elastic_linearization(rob, qa, coord: tuple):
    # the linearisation of the rigid robot about rest with the non-elastic joints held, i.e.
    # jflex.linearize of Model(rob, []) (tests/test_gap.py checks the two agree), from the crba and
    # gravity kernels: a diagnosis asks for it at every posture of every candidate structure, where
    # tracing a linearize, or compiling one per structure, costs seconds each time
    ix = jnp.ix_(jnp.array(coord), jnp.array(coord))
    return crba(rob, qa)[ix], gravity_stiffness(rob, qa)[ix]


class FrequencyModel:
    """FRFs and modes of a :class:`Structure` at postures, parameters in log form:
    ``[log k_s, log c_s for each site, the payload's (:data:`PAYLOAD_NAMES`), atanh r of each coupled
    pair]`` (``c_s = k_s theta_s`` the loss stiffness of the site's law)."""

    def __init__(self, robot, structure: Structure, tool_frame):
        self.robot, self.structure, self.tool = robot, structure, tool_frame
        self.aug, self.coord, self.model_index = augment(robot, structure.springs)
        self.pairs = structure.pairs()
        elastic = set(int(c) for c in self.coord)
        self.held = tuple(nm for i, nm in enumerate(self.aug.joint_names) if i not in elastic)
        self._cache = {}
        self._psi_cache = {}

    def _tool(self):
        return self.tool if self.tool is not None else self.aug.link_names[-1]

    def _payload_frame(self):
        """(body index, the tool frame's pose (4, 4) in the body's frame) of the tool payload (made
        once: every evaluation at a new ``x`` asks for it)."""
        hit = self.__dict__.get("_pframe")
        if hit is None:
            body, k = self.aug.frame_index(self._tool())
            T = np.eye(4)
            if k >= 0:
                T[:3, :3], T[:3, 3] = np.asarray(self.aug.frame_R[k]), np.asarray(self.aug.frame_p[k])
            hit = self._pframe = (body, T)
        return hit

    def _n_payload(self) -> int:
        return int(self.structure.payload)

    def payload_parameters(self, x) -> dict:
        """The fitted payload in the tool frame: mass [kg], centre of mass [m], inertia about it
        [kg m^2] (Pinocchio's order ``Ixx, Ixy, Iyy, Ixz, Iyz, Izz``), and its 10 inertial parameters
        about the link's frame."""
        P = self._n_payload()
        th = np.asarray(x, float)[2 * len(self.structure.springs):][:P]
        m, c, Ic = (np.asarray(a) for a in params_to_com(payload_inertia(th)))  # about the tool frame
        m = float(m)
        body, T = self._payload_frame()
        return {"mass [kg]": m, "com (tool frame) [m]": [float(v) for v in c],
                "inertia about com (tool axes) [kg m^2]": [float(Ic[i, j]) for i, j in ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))],
                "parameters": P, "link": self.aug.link_names[body],
                "inertial parameters (link frame)": [float(v) for v in payload_inertia(th, T)]}

    def posture(self, q0) -> np.ndarray:
        """The augmented robot's coordinates at the model posture ``q0`` (virtual joints at 0)."""
        qa = np.zeros(self.aug.nq)
        qa[self.model_index] = q0
        return qa

    def _linearization(self, rob, qa, traced: bool = False):
        """``(M, K_g)`` over the elastic coordinates, in site order: the linearisation of the rigid
        augmented robot ``rob`` with every other joint held."""
        M, K = _elastic_linearization(rob, jnp.asarray(qa), tuple(int(c) for c in self.coord))
        return (M, K) if traced else (np.asarray(M), np.asarray(K))

    def mats(self, q0) -> PostureMats:
        q0 = np.asarray(q0, float)
        fast = q0.tobytes()  # the exact posture array a fit passes again and again (a bytes key:
        hit = self._cache.get(fast)  # no clash with the rounded tuple keys in the same dict)
        if hit is not None:
            return hit
        key = tuple(np.round(q0, 12))
        if key in self._cache:
            self._cache[fast] = self._cache[key]
            return self._cache[key]
        qa = self.posture(q0)
        M, Kg = self._linearization(self.aug, qa)
        J = np.asarray(jacobian(self.aug, jnp.asarray(qa), self._tool(), "local_world_aligned"))[:3][:, self.coord]
        dM = dKg = None
        if self.structure.payload:
            dM, dKg = self._payload_basis(qa)
        out = PostureMats(M, Kg, J, dM, dKg)
        self._cache[key] = self._cache[fast] = out
        return out

    def _payload_basis(self, qa):
        """The payload's share of ``M`` and ``K_g``, both linear in its 10 inertial parameters ``pi``
        (about its link's frame): their derivatives in them (S, S, 10). ``M``'s is ``J_b^T
        Lambda(pi) J_b``, ``J_b`` the link's Jacobian in its own frame and ``Lambda`` the spatial
        inertia; ``K_g``'s (mass and first moment only) the gravity stiffness of the payload alone
        (a forward-mode derivative of the linearisation in ``pi`` costs ~30 times more, outside
        ``jit``)."""
        body = self._payload_frame()[0]
        coord = np.asarray(self.coord)
        Jb = np.asarray(jacobian(self.aug, jnp.asarray(qa), body, "local"))[:, coord]  # (6, S): [v; w]
        S = coord.size
        dM = np.zeros((S, S, 10))
        for i in range(10):
            e = np.zeros(10)
            e[i] = 1.0
            hx = np.asarray(skew(e[1:4]))
            Lam = np.block([[e[0] * np.eye(3), -hx], [hx, np.asarray(inertia_matrix3(e))]])
            dM[:, :, i] = Jb.T @ Lam @ Jb
        dKg = np.zeros((S, S, 10))
        ix = np.ix_(coord, coord)
        for i in range(4):
            inert = np.zeros(np.shape(self.aug.inertia))
            inert[body, i] = 1.0
            dKg[:, :, i] = np.asarray(gravity_stiffness(self.aug.replace(inertia=inert), jnp.asarray(qa)))[ix]
        return dM, dKg

    def _split(self, x):
        x = np.asarray(x, float)
        xb = x.tobytes()
        last = getattr(self, "_last_split", None)
        if last is not None and last[0] == xb:
            return last[1]  # a fit evaluates every posture and data set at one x
        S = len(self.structure.springs)
        xc = np.clip(x, -60.0, 60.0)  # log parameters: keep exp() finite while the solver explores
        # the payload's 10 inertial parameters about its link's frame (None: no payload)
        P = self._n_payload()
        pi = payload_inertia(x[2 * S:2 * S + P], self._payload_frame()[1]) if P else None
        out = (np.exp(xc[:S]), np.exp(xc[S:2 * S]), pi)
        self._last_split = (xb, out)
        return out

    def widths(self) -> np.ndarray:
        """Half-width of each parameter's box about a fit's start (:func:`fit_linear`): a factor
        ``e^3`` for stiffnesses, couplings and the payload's mass, ``e^4`` for damping; NaN for the
        parameters held in a fixed box (:meth:`absolute_bounds`)."""
        S = len(self.structure.springs)
        P = self._n_payload()
        w = np.full(2 * S + P + len(self.pairs), 3.0)
        w[S:2 * S] = 4.0
        w[2 * S + 1:2 * S + P] = np.nan
        return w

    def absolute_bounds(self):
        """``(lo, hi)`` of the parameters held in a fixed box whatever a fit's start (NaN for the
        rest): the payload's centre of mass within :data:`PAYLOAD_COM_BOX` of the tool frame's
        origin, and the factor of its second moment (radii of gyration from 2 mm to that box, its
        off-diagonal terms within it). (Boxes about the start let a light payload's centre of mass
        walk away with each refit of a later candidate: 0.7 m out on the independent link-bending
        case.)"""
        S = len(self.structure.springs)
        P = self._n_payload()
        lo = np.full(2 * S + P + len(self.pairs), np.nan)
        hi = lo.copy()
        o = 2 * S
        B = PAYLOAD_COM_BOX
        for i in range(1, P):
            lo[o + i], hi[o + i] = (np.log(0.002), np.log(B)) if 4 <= i <= 6 else (-B, B)
        return lo, hi

    def coupling(self, x):
        """``r`` (in (-1, 1)) of each coupled pair."""
        o = 2 * len(self.structure.springs) + self._n_payload()
        return np.tanh(np.asarray(x, float)[o:o + len(self.pairs)])

    def stiffness_matrix(self, x) -> np.ndarray:
        """The sites' static stiffness (S, S) [N m/rad], couplings included."""
        k, _, _ = self._split(x)
        K = np.diag(k)
        for (a, b), r in zip(self.pairs, self.coupling(x)):
            K[a, b] = K[b, a] = r * np.sqrt(k[a] * k[b])
        return K

    def model(self, x) -> Model:
        """The :class:`jflex.Model` these parameters stand for: the augmented robot with the sites'
        springs (:class:`jflex.effects.Spring`), each site's law on its own stiffness
        (:class:`jflex.effects.StructuralDamping`) and the payload (:class:`jflex.effects.Payload`).
        Hold :attr:`held` to analyse it as the diagnosis does."""
        k, c, pi = self._split(x)
        names = list(self.aug.joint_names)
        effects = [Spring([names[i] for i in self.coord], self.stiffness_matrix(x))]
        for i, s in enumerate(self.structure.springs):
            effects.append(StructuralDamping(jnp.array([[k[i]]]), with_loss(s.law, c[i] / k[i]), coords=(int(self.coord[i]),),
                                             name=f"site{i}"))
        if self.structure.payload:
            effects.append(Payload(pi, link=self.aug.link_names[self._payload_frame()[0]]))
        return Model(self.aug, effects)

    def _psi(self, w, tabulated: bool = False):
        """(F, S) unit loss of every site's law at ``w`` (F,): one lookup per grid, one law
        evaluation per distinct law (a fit asks for the same grids hundreds of thousands of times)."""
        ck = None if tabulated else (w.shape, w.tobytes())  # a modal iteration's w never recurs
        hit = self._psi_cache.get(ck)
        if hit is None:
            laws = {}
            for sp in self.structure.springs:
                laws.setdefault(id(sp.law), sp.law)
            vals = {i: unit_loss(law, w, tabulated) for i, law in laws.items()}
            hit = np.stack([vals[id(sp.law)] for sp in self.structure.springs], axis=-1) if self.structure.springs else np.zeros(w.shape + (0,), complex)
            if ck is not None:
                if len(self._psi_cache) > 256:
                    self._psi_cache.clear()
                self._psi_cache[ck] = hit
        return hit

    def _static(self, x, P: PostureMats):
        """``(K_0, M)`` at ``x``: the frequency-independent stiffness (``K_g`` with the payload's
        share, the pairs' couplings) and the mass matrix."""
        k, c, pi = self._split(x)
        M, Kg = P.M, P.Kg
        if P.dM is not None and pi is not None:
            M, Kg = M + P.dM @ pi, Kg + P.dKg @ pi
        K0 = np.array(Kg, float)
        for (a, b), r in zip(self.pairs, self.coupling(x)):
            K0[a, b] += r * np.sqrt(k[a] * k[b])
            K0[b, a] += r * np.sqrt(k[a] * k[b])
        return K0, M

    @staticmethod
    def _grid(P: PostureMats, key, make):
        """A law-independent array of posture ``P`` on a data grid, made once (a fit asks for the
        same few grids hundreds of thousands of times)."""
        g = P.derived.setdefault("grid", {})
        hit = g.get(key)
        if hit is None:
            if len(g) > 64:
                g.clear()
            hit = g[key] = make()
        return hit

    def _jt(self, P: PostureMats, F: int):
        """``J^T`` (F, S, 3), complex: the solves' right-hand side."""
        return self._grid(P, ("Jt", F), lambda: np.broadcast_to(P.J.T, (F,) + P.J.T.shape).astype(complex))

    def stiffness(self, x, P: PostureMats, omega, tabulated: bool = False):
        """Dynamic stiffness (F, S, S) at angular frequencies ``omega`` (F,) (``tabulated``: see
        :func:`unit_loss`)."""
        k, c, _ = self._split(x)
        K0, M = self._static(x, P)
        w = np.asarray(omega, float)
        S = len(k)
        # the static part (K_g, couplings) once, then the frequency-dependent terms on the (F, S, S)
        # (-w^2 M kept per posture and data grid while M is the posture's own: no payload)
        if M is P.M and not tabulated:
            w2M = self._grid(P, ("w2M", w.tobytes()), lambda: (w * w)[:, None, None] * -M)
        else:
            w2M = (w * w)[:, None, None] * -M
        D = np.empty((w.size, S, S), complex)
        np.add(w2M, K0, out=D.real)
        D.imag[:] = 0.0
        D.reshape(w.size, S * S)[:, ::S + 1] += k + c * self._psi(w, tabulated)  # the diagonal
        return D, M

    def _solve(self, x, P: PostureMats, w):
        """``(D, D^{-1} J^T, H)`` at ``x`` on the grid ``w``, kept for the last ``x`` per posture and
        grid: a fit's Jacobian (:meth:`frf_jacobian`) comes at the ``x`` its residual just had."""
        xb, wb = np.asarray(x, float).tobytes(), w.tobytes()
        memo = self.__dict__.setdefault("_solves", {})
        hit = memo.get((id(P), wb))
        if hit is not None and hit[0] is P and hit[1] == xb:
            return hit[2]
        D, _ = self.stiffness(x, P, w)
        G = np.linalg.solve(D, self._jt(P, w.size))
        out = (D, G, P.J[None] @ G)
        if len(memo) > 64:
            memo.clear()
        memo[(id(P), wb)] = (P, xb, out)  # P kept alive with its id
        return out

    @_quiet
    def frf(self, x, q0, freq_hz):
        """Tool receptance (F, 3, 3) [m/N]."""
        P = self.mats(q0)
        if len(self.structure.springs) == 0:
            return np.zeros((len(freq_hz), 3, 3), complex)
        return self._solve(x, P, 2 * np.pi * np.asarray(freq_hz, float))[2].copy()

    @_quiet
    def frf_jacobian(self, x, q0, freq_hz):
        """Tool receptance ``H`` (F, 3, 3) and its derivatives (P, F, 3, 3) in the log parameters ``x``:
        ``dH = -J D^{-1} (dD/dx_p) D^{-1} J^T``, one solve for all of them (the finite differences
        this replaces cost one FRF per parameter)."""
        P = self.mats(q0)
        S = len(self.structure.springs)
        x = np.asarray(x, float)
        w = 2 * np.pi * np.asarray(freq_hz, float)
        D, G, H = self._solve(x, P, w)  # G = D^-1 J^T (F, S, 3)
        # (J D^-1)^T: D's own solve when D is symmetric (its matrices are)
        Lt = G if P.symmetric() else np.linalg.solve(np.swapaxes(D, 1, 2), self._jt(P, w.size))
        k, c, _ = self._split(x)
        live = np.abs(x) < 60.0  # _split clips there: no derivative beyond
        dH = np.zeros((x.size, w.size, 3, 3), complex)

        psi = self._psi(w)
        if S:
            # dD = v (F,) at (i, i): d(k + c psi) / d log k = k, / d log c = c psi
            LtT, GT = Lt.transpose(1, 0, 2)[:, :, :, None], G.transpose(1, 0, 2)[:, :, None, :]
            dH[:S] = (-np.broadcast_to(k[:, None], (S, w.size)).astype(complex))[:, :, None, None] * LtT * GT
            dH[S:2 * S] = (-(c * psi).T)[:, :, None, None] * LtT * GT
        o = 2 * S
        if self.structure.payload:
            # dD / d theta_p = (dK_g - w^2 dM) . d pi / d theta_p
            npl = self._n_payload()
            _, dpi = payload_inertia(x[o:o + npl], self._payload_frame()[1], jac=True)
            LtT = np.swapaxes(Lt, 1, 2)
            for p_, dp in enumerate(dpi):
                # -(J D^-1)(dK - w^2 dM)(D^-1 J^T) by batched products (a three-operand einsum
                # summed it naively: the payload's columns were most of a round's refit time)
                dK, dMp = P.dKg @ dp, P.dM @ dp
                dH[o + p_] = (w**2)[:, None, None] * ((LtT @ dMp) @ G) - (LtT @ dK) @ G
            o += npl
        for q, ((a, b), r) in enumerate(zip(self.pairs, self.coupling(x))):
            # dD = v (F,) at (a, b) and (b, a): dH = -v J D^-1 (e_a e_b^T + e_b e_a^T) D^-1 J^T
            X = Lt[:, a, :, None] * G[:, b, None, :] + Lt[:, b, :, None] * G[:, a, None, :]
            kab = np.sqrt(k[a] * k[b])
            half = np.full(w.size, 0.5 * r * kab, complex)[:, None, None] * X
            dH[a] -= half  # d(r sqrt(k_a k_b)) / d log k_a
            dH[b] -= half
            dH[o + q] -= np.full(w.size, (1 - r**2) * kab, complex)[:, None, None] * X
        dH[~live] = 0.0
        return H.copy(), dH

    @_quiet
    def modes(self, x, q0):
        """(f [Hz], zeta) of the elastic modes, sorted; light-damping approximation: shapes from
        the real stiffness, ``w_r^2`` its Rayleigh quotient at ``w_r`` (iterated for frequency-
        dependent laws), ``zeta_r = phi^T Im D(w_r) phi / (2 w_r^2 phi^T M phi)``.

        (The real and imaginary parts of ``D`` are built apart, without the complex (modes, S, S)
        stack, in the same floating-point operations as :meth:`stiffness`: the fits' picked-peak
        phases, which call this per data set and trial ``x``, stay bit for bit what they were; an
        algebraically equal shortcut, ``K_0 + diag(Re d)``, moved the independent UR5 FRF case's second selected
        effect.)"""
        P = self.mats(q0)
        S = len(self.structure.springs)
        if S == 0:
            return np.zeros(0), np.zeros(0)
        frac = self.__dict__.get("_frac")
        if frac is None:
            frac = self._frac = any(frequency_dependent(s.law) for s in self.structure.springs)
        w_ref = 2 * np.pi * 10.0
        psi_ref = self.__dict__.get("_psi_ref")
        if psi_ref is None:
            psi_ref = self._psi_ref = self._psi(np.array([w_ref]), True)
        k, c, _ = self._split(x)
        K0, M = self._static(x, P)
        nM = -M
        diag = slice(None, None, S + 1)

        def real_part(w, psi):  # Re D(w) (F, S, S)
            R = (w * w)[:, None, None] * nM
            R += K0
            R.reshape(w.size, S * S)[:, diag] += (k + c * psi).real
            return R

        A = real_part(np.array([w_ref]), psi_ref)[0] + w_ref**2 * M
        lam, V = _gen_eig(A, M)
        w = np.sqrt(np.maximum(lam, 1e-12))
        den = np.einsum("ir,ij,jr->r", V, M, V)
        for _ in range(4 if frac else 1):
            K = real_part(w, self._psi(w, True))
            K += (w**2)[:, None, None] * M
            w = np.sqrt(np.maximum(np.einsum("ir,rij,jr->r", V, K, V) / den, 1e-12))
        Dw = np.zeros((w.size, S, S), complex)
        Dw.reshape(w.size, S * S)[:, diag] += k + c * self._psi(w, True)
        z = np.einsum("ir,rij,jr->r", V, Dw.imag, V) / (2 * w**2 * den)
        o = np.argsort(w)
        return w[o] / (2 * np.pi), z[o]


def _gen_eig(K, M):
    try:
        L = np.linalg.cholesky(M + 1e-12 * np.trace(M) * np.eye(len(M)))
    except np.linalg.LinAlgError:
        # a non-physical mass matrix (e.g. a base-parameter realisation seen through a virtual
        # joint): no modes; the candidate's residuals become large and it is not selected
        return np.full(len(M), np.nan), np.eye(len(M))
    Li = np.linalg.inv(L)
    A = Li @ K @ Li.T
    lam, U = np.linalg.eigh(0.5 * (A + A.T))
    return lam, Li.T @ U
