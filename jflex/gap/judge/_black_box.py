"""The noise floor of a torque record that does not repeat: the held-out error of flexible
black-box models of the nominal residual, an upper bound of the noise (what a smooth function of
the motion, or of its history, cannot predict)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..torque._set import _filtered, _product
from ._periodic import effective_samples


BLACK_BOX_BLOCKS = 32  # contiguous blocks, alternately held out (split-half cross-validation)
BLACK_BOX_FEATURES = 200  # random Fourier features of the motion, at most
# per joint: cosine series of these lengths in the joint's angle over its range, one model each
# (a series too long for the data chases the held-out blocks' edges, one too short misses a fast
# ripple; the data say which, as for the other models, on held-out blocks)
BLACK_BOX_HARMONICS = (8, 16, 32)
UNPREDICTED = 0.95  # a channel whose held-out bound keeps this share of its own residual's RMS


RIDGE_GRID = np.geomspace(1e-8, 1.0, 17)  # penalties, relative to the largest eigenvalue of the Gram


class _Moments:
    """Per-block sums of a feature matrix ``A`` (N, p) and targets ``Y`` (N, k) (counts, sums, Gram
    ``A_b^T A_b``, ``A_b^T Y_b``, ``sum Y_b^2``): every ridge fit and held-out error of the
    block cross-validation below is a sum over blocks of these, so the samples are read once
    however many models, folds and penalties are tried."""

    def __init__(self, A, Y, ids, nblk):
        sums = []
        for b in range(nblk):  # one block's rows at a time: never a second copy of A
            a, y = A[ids == b], Y[ids == b]
            sums.append((len(a), a.sum(axis=0), y.sum(axis=0), a.T @ a, a.T @ y, np.sum(y**2, axis=0)))
        n, sA, sY, G, C, yy = zip(*sums)
        self.n, self.sA, self.sY = np.array(n, float), np.stack(sA), np.stack(sY)
        self.G, self.C, self.yy = np.stack(G), np.stack(C), np.stack(yy)

    def centred(self, blocks, cols, mp, mr):
        """Gram, cross and target sums of the blocks ``blocks`` on the columns ``cols``, centred at
        the feature means ``mp`` and target means ``mr`` (a fold's training means)."""
        n = self.n[blocks].sum()
        sA, sY = self.sA[blocks].sum(axis=0)[cols], self.sY[blocks].sum(axis=0)
        G = self.G[blocks].sum(axis=0)[np.ix_(cols, cols)]
        G = G - np.outer(sA, mp) - np.outer(mp, sA) + n * np.outer(mp, mp)
        C = self.C[blocks].sum(axis=0)[cols]
        C = C - np.outer(sA, mr) - np.outer(mp, sY) + n * np.outer(mp, mr)
        yy = self.yy[blocks].sum(axis=0) - 2 * mr * sY + n * mr**2
        return G, C, yy


def _eig(G, C):
    """The Gram's eigenvalues ``w`` (ascending, rounding below 0 cut), vectors ``V`` and ``V^T C``:
    the ridge coefficients for a penalty ``lam`` are then ``V (V^T C / (w + lam))``."""
    w, V = np.linalg.eigh(G)
    return np.maximum(w, 0.0), V, V.T @ C


def _ridge_blocks(mom, blocks, cols, mp, mr):
    """Ridge regression coefficients (p, k) fitted on the blocks ``blocks``, each target column's
    penalty chosen on a log grid by two-fold cross-validation over alternate blocks of these
    training blocks themselves: consecutive samples share their noise, so a penalty judged
    sample by sample (leave-one-out, GCV) lets the black box chase the noise between blocks."""
    G, C, _ = mom.centred(blocks, cols, mp, mr)
    w, V, VtC = _eig(G, C)
    grid = max(float(w[-1]), 1e-300) * RIDGE_GRID
    cv = np.zeros((len(grid), C.shape[1]))
    for f in (0, 1):
        trb, teb = blocks[f::2], blocks[1 - f::2]
        if not len(trb) or not len(teb):
            continue
        Gt, Ct, _ = mom.centred(trb, cols, mp, mr)
        Ge, Ce, yye = mom.centred(teb, cols, mp, mr)
        wt, Vt_, VtCt = _eig(Gt, Ct)
        for i, lam in enumerate(grid):
            B = Vt_ @ (VtCt / (wt + lam)[:, None])
            # the held-out blocks' squared error from their sums: |y|^2 - 2 B.c + B^T G B
            cv[i] += yye - 2 * np.sum(B * Ce, axis=0) + np.sum(B * (Ge @ B), axis=0)
    lam = grid[np.argmin(cv, axis=0)]
    return V @ (VtC / (w[:, None] + lam[None, :]))


def black_box_noise(s, resid, m, seed: int = 0):
    """Per-channel torque noise [N m] of a record that does not repeat: the held-out RMS of a
    flexible black-box model of the nominal residual ``resid`` (N, n) [N m], fitted (ridge) on
    alternate blocks of the record and tested on the others, both ways. The model is a smooth
    function of the motion (random Fourier features of the angles' sines and cosines, rates and
    accelerations; each joint's rate, acceleration and smoothed sign of the rate; the nominal
    torque's time derivative): a structured model error (friction, inertia, a delay, a payload)
    is a function of the motion and is predicted, noise is not. The same fit on the per-joint
    terms alone (no random features, a penalty of their own) is a second bound, and the per-joint
    terms with a cosine series in each joint's angle over its range (a ripple that repeats with
    the angle: cogging, a transmission error) a third; when ``s`` carries the rigid-body regressor
    ``Y`` (N, n, 10 n), the per-joint terms with each channel's own row of it (an inertial error is
    linear in it) a fourth; each channel takes the smallest. An upper bound of the noise (what the
    models cannot represent stays in it).
    Returns ``(sigma, dof, info)``; ``info["base_only"]``: the channels whose bound came from the
    per-joint terms, ``info["angle_series"]``: those whose bound came from the angle series,
    ``info["rigid_body"]``: those whose bound came from the regressor rows, ``info["history"]``:
    those whose bound came from the per-joint terms with the joint's motion through plays
    (:func:`_history_terms`: a residual that depends on the motion's history)."""
    N, n = resid.shape
    f = _black_box_features(s, N, seed)
    mom = _Moments(f.A, resid, f.ids, BLACK_BOX_BLOCKS)
    nrff = f.Phi.shape[1]
    base_cols = np.arange(f.nb)
    models = [np.arange(nrff), base_cols]
    for K in f.Ks:
        # the series' columns are joint-major, K per moving joint: the first K of each
        sel = (np.arange(f.n_moving)[:, None] * f.Kmax + np.arange(K)[None, :]).ravel()
        models.append(np.concatenate([base_cols, nrff + sel]))

    # the random features' penalty shrinks the base terms with them: a light joint's viscous
    # friction (a Panda's joint 7, 12 % of its torque) was left 40 % unpredicted, its floor 14 x
    # the noise. Every model's held-out error bounds the noise from above: each channel takes the
    # tightest
    errs = [_held_out(c, mom, f.A, resid, f.ids) for c in models]
    rigid_at = -1  # where the per-channel models' errors sit in errs (-1: no such model)
    Y = getattr(s, "Y", None)
    if Y is not None and f.nb + Y.shape[2] <= N // 8:
        # the per-joint terms with the channel's own rigid-body regressor row: an inertial error
        # (CAD masses, a payload) is linear in it, but through sums of angles and products of
        # rates the smooth features above reach only roughly (a UR5 shoulder's bound stayed at
        # 4 x its noise with a 7 % mass error)
        # through the set's parallel filter: the copy the inertial refit made and keeps with the set
        Yf = _filtered(s, "Y") if hasattr(s, "cache") else Y
        rigid_at = len(errs)
        errs.append(_per_channel_errors(resid, m, f, lambda j: Yf[:, j, :]))
    # the per-joint terms with the joint's motion through plays of a few widths (the displacement a
    # play leaves and its rates): a residual that depends on the motion's history (gear play, a
    # hysteresis: which side of a gap the teeth are on) is no function of the present motion, and
    # the smooth features kept it as noise (a 3-joint arm's play: floor 32.3 % against a 31.8 % gap)
    history_at = len(errs)
    errs.append(_per_channel_errors(resid, m, f, lambda j: _history_terms(s, j)))
    if hasattr(s, "cache"):
        # kept for the channels of this call only: 70 MB on a 5 kHz 6-joint record, read by nothing
        # else (a second floor of the same set makes them again, the same)
        s.cache.pop("history_terms", None)
    return _tightest(errs, resid, m, f, len(models), rigid_at, history_at)


@dataclasses.dataclass(frozen=True)
class _Features:
    """The black box's columns of one record: ``Phi`` the per-joint base terms (the first ``nb``)
    then the random features; ``A`` the same followed by the angle series (joint-major, ``Kmax``
    per moving joint, ``n_moving`` of them; the series of each length in ``Ks`` nest in it);
    ``ids`` each sample's block."""

    Phi: np.ndarray
    A: np.ndarray
    nb: int
    Ks: list
    Kmax: int
    n_moving: int
    ids: np.ndarray


def _zscore(v):
    sd = v.std(axis=0)
    return (v - v.mean(axis=0)) / np.where(sd > 0, sd, 1.0)


def _black_box_features(s, N: int, seed: int) -> _Features:
    """The black box's feature matrices for the torque set ``s`` of ``N`` samples (see
    :func:`black_box_noise`)."""
    q, qd, qdd = (np.asarray(v, float) for v in (s.q, s.qd, s.qdd))
    h = float(np.mean(np.diff(s.t)))
    z = _zscore
    v0 = 0.05 * np.maximum(qd.std(axis=0), 1e-12)
    base = [np.ones((N, 1)), z(qd), z(qdd), np.tanh(qd / v0), np.sin(q), np.cos(q),
            z(np.gradient(np.asarray(s.F0, float), h, axis=0))]
    Z = np.concatenate([np.sin(q), np.cos(q), z(qd), z(qdd)], axis=1)
    rng = np.random.default_rng(seed)
    M = int(max(0, min(BLACK_BOX_FEATURES, N // 8 - sum(b.shape[1] for b in base))))
    W = rng.standard_normal((Z.shape[1], M)) / np.sqrt(Z.shape[1])
    Phi = np.concatenate(base + [np.cos(Z @ W + rng.uniform(0, 2 * np.pi, M))], axis=1)
    sd = Phi.std(axis=0)
    Phi = np.where(sd > 0, (Phi - Phi.mean(axis=0)) / np.where(sd > 0, sd, 1.0), 1.0)
    ids = np.arange(N) * BLACK_BOX_BLOCKS // N
    nb = sum(b.shape[1] for b in base)
    # the random features are smooth in the angles (a few radians per cycle): a ripple of many
    # cycles per turn, a function of one angle, is beyond them (a 3-joint arm's cogging at 27
    # cycles a turn stayed in the floor, 4.1 % against 0.7 % of noise, and a spring was
    # `explained` inside it); a series in each angle alone reaches it with few terms
    span = np.ptp(q, axis=0)
    mv = np.flatnonzero(span > 1e-9)
    u = (q[:, mv] - q[:, mv].min(axis=0)) / np.where(span[mv] > 0, span[mv], 1.0)
    Ks = [K for K in BLACK_BOX_HARMONICS if len(mv) and nb + K * len(mv) <= N // 8]
    # one feature matrix holds every model's columns (the angle series nest: 8 in 16 in 32)
    Kmax = max(Ks, default=0)
    series = [z(np.cos(np.pi * u[:, :, None] * np.arange(1, Kmax + 1)).reshape(N, -1))] if Kmax else []
    A = np.concatenate([Phi] + series, axis=1)
    return _Features(Phi, A, nb, Ks, Kmax, len(mv), ids)


def _held_out(cols, mom, A, target, ids):
    """Held-out error (N, k) of the ridge model on the columns ``cols`` of ``A`` for ``target``,
    fitted on alternate blocks (``ids``: each sample's block) and tested on the others, both ways."""
    nbk = BLACK_BOX_BLOCKS
    err = np.zeros_like(target)
    P = A[:, cols]
    for f in (0, 1):
        trb = np.arange(f, nbk, 2)
        tr, te = ids % 2 == f, ids % 2 != f
        # the intercept is not penalised: a constant share of the residual (a sensor offset, a
        # weight the sensor does not report) is a model error, never noise, however large it is
        mr, mp = target[tr].mean(axis=0), P[tr].mean(axis=0)
        B = _ridge_blocks(mom, trb, cols, mp, mr)
        err[te] = target[te] - mr - (P[te] - mp) @ B
    return err


def _per_channel_errors(resid, m, f: _Features, extra):
    """Held-out errors of the per-joint terms with ``extra(j)`` (N, k) for each channel ``j`` in
    the gap; a channel whose record is too short for them keeps its residual (no bound)."""
    N, nb, Phi, ids = resid.shape[0], f.nb, f.Phi, f.ids
    err = resid - resid.mean(axis=0)
    for j in np.flatnonzero(np.asarray(m, bool)):
        Xj = extra(j)
        if nb + Xj.shape[1] > N // 8:
            continue
        Aj = np.concatenate([Phi[:, :nb], Xj], axis=1)
        sd = Aj.std(axis=0)
        Aj = np.where(sd > 0, (Aj - Aj.mean(axis=0)) / np.where(sd > 0, sd, 1.0), 0.0)
        cols = np.flatnonzero(sd > 0)
        mj = _Moments(Aj, resid[:, j:j + 1], ids, BLACK_BOX_BLOCKS)
        err[:, j] = _held_out(cols, mj, Aj, resid[:, j:j + 1], ids)[:, 0]
    return err


def _tightest(errs, resid, m, f: _Features, n_models: int, rigid_at: int, history_at: int):
    """Each channel's tightest bound among the models' held-out errors ``errs`` (the first
    ``n_models`` on every channel, then the per-channel models at ``rigid_at`` and ``history_at``):
    ``(sigma, dof, info)`` of :func:`black_box_noise`."""
    n = resid.shape[1]
    rms = np.stack([np.sqrt(np.mean(e**2, axis=0)) for e in errs])
    for k in (rigid_at, history_at):  # channels left out of the gap hold no per-channel model's error
        if k >= 0:
            rms[k, ~np.asarray(m, bool)] = np.inf
    pick = np.argmin(rms, axis=0)
    err = np.stack([errs[pick[j]][:, j] for j in range(n)], axis=1)
    sig = rms[pick, np.arange(n)]
    dof = np.array([effective_samples(err[:, j]) if m[j] else 1.0 for j in range(n)])
    mk = np.asarray(m, bool)
    # a channel no model predicted any of: its bound is its own residual, noise or an error that is
    # no function of the motion (the floor cannot tell which)
    own = np.sqrt(np.mean((resid - resid.mean(axis=0)) ** 2, axis=0))
    unpredicted = [int(j) for j in np.flatnonzero(mk & (sig >= UNPREDICTED * own) & (own > 0))]
    return sig, dof, dict(features=int(f.Phi.shape[1]), base_features=int(f.nb), blocks=BLACK_BOX_BLOCKS,
                          unpredicted=unpredicted,
                          harmonics=f.Ks, base_only=[int(j) for j in np.flatnonzero((pick == 1) & mk)],
                          angle_series=[int(j) for j in np.flatnonzero((pick >= 2) & (pick < n_models) & mk)],
                          rigid_body=[int(j) for j in np.flatnonzero((pick == rigid_at) & mk)],
                          history=[int(j) for j in np.flatnonzero((pick == history_at) & mk)])


# [rad] half-widths of the plays the history terms pass each angle through: fine enough that one
# lies near any gear's (the engagement's timing, which the torque shows, moves with the width)
HISTORY_WIDTHS = tuple(np.geomspace(0.001, 0.03, 12))


def _history_terms(s, j: int) -> np.ndarray:
    """Columns of the motion's history for channel ``j``, through the set's parallel filter: for
    each width ``b`` of :data:`HISTORY_WIDTHS`, the displacement a play of half-width ``b`` leaves
    at joint ``j`` (``play(q_j, b) - q_j``, the side of the gap it sits on) and its first and
    second rates; and, for every moving joint ``k``, the change of joint ``j``'s rigid torque when
    link ``k`` lags by its own play's displacement (the nominal model's inertia and gravity weigh
    it with the posture; a play at one joint loads the others through the inertia matrix)."""
    from ..torque._terms import link_lag_column, play

    def make():
        q = np.asarray(s.q, float)
        h = float(np.mean(np.diff(s.t)))
        moving = [k for k in range(q.shape[1]) if np.ptp(q[:, k]) > 1e-9]
        own, lagged = {}, []
        for k in moving:
            for b in HISTORY_WIDTHS:
                d = play(q[:, k], b) - q[:, k]
                dd = np.gradient(d, h)
                own.setdefault(k, []).extend([d, dd, np.gradient(dd, h)])
                if getattr(s, "robot", None) is not None:
                    lagged.append(link_lag_column(s, k, d))  # (N, n)
        lp = s.lp if hasattr(s, "lp") else (lambda X: X)
        L_ = lp(np.stack(lagged, axis=2).reshape(q.shape[0], -1)).reshape(q.shape + (len(lagged),)) if lagged \
            else np.zeros(q.shape + (0,))
        return {k: lp(np.stack(v, axis=1)) for k, v in own.items()}, L_

    own, L_ = _product(s, "history_terms", make) if hasattr(s, "cache") else make()
    return np.concatenate([own.get(j, np.zeros((L_.shape[0], 0))), L_[:, j, :]], axis=1)
