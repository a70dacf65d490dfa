"""The tracker as an immutable configuration, a mutable state and one step.

Following the model/data split of pinocchio: a :class:`StepConfig` (the
interval model, validated settings and the constants derived from them, the
backend) never changes during a run; a :class:`TrackerState` holds everything
that does (boxes of every geometry hypothesis, the window of past boxes and
readings the velocity baselines use, mode streaks, inconsistencies); and
:func:`step` advances the state by one sample.  :class:`verifier.tracker.Tracker`
bundles one of each for online use (``update(q)``); :func:`verifier.tracker.track`
and :func:`verifier.tracker.track_batch` are loops over the same step.

Two implementations of one small step protocol (:class:`StepImpl`) compute
the same step, chosen by the user-facing :class:`Backend`:

* ``"compiled"`` (default, :class:`~verifier.compiled.driver.CompiledStep`): numba kernels
  (:mod:`verifier.compiled`), no Python per operation, no allocation per
  sample; scenarios in parallel for batches;
* ``"numpy"`` (:class:`NumpyStep`): the reference, vectorised over rows.

Inside the step, the velocity model is a strategy of its own in both
(:class:`VelocityInfo`: :class:`Displacement` for ``SOUND``,
:class:`JointRates` for ``PAPER`` and ``JOINT_FD``; the compiled ones are
chosen by type, so numba compiles only the model in use,
:func:`verifier.compiled.step.velocity_strategy`).

Both read the same :class:`verifier.constants.StepConstants` by name and
follow the same float operations; their boxes agree bit for bit except
where numpy's and the C library's ``sin``/``cos`` differ in the last bits
(both inside the :data:`verifier.interval.TRIG_ULPS` margin).

Rows ``r = b P + p`` of the state hold geometry hypothesis ``p`` of scenario
``b``; each row runs its own contraction fixpoint, so a scenario's result does
not depend on the other scenarios of its batch.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np

from crosscert.robots.errors import InputError

from . import interval as I
from .compiled.driver import CompiledStep
from .constants import JOINT_FD, PAPER, SOUND, StepConstants, pack_constants
from .contractors import hc4_pose, mode_of, newton, split_prune, velocity, velocity_displacement
from .contractors import pose_solutions as _np_pose_solutions
from .linalg import linear_enclosure
from .state import TrackerState

__all__ = ["Backend", "StepConfig", "TrackerState", "StepResult", "Event", "configure", "init_state", "partition_xi", "step",
           "checked_sample",
           "advance", "pose_solutions", "pose_solution_arrays", "reading_box", "kernel_array", "StepImpl", "NumpyStep",
           "CompiledStep"]


def reading_box(q, eps):
    """The box the tracker gives readings ``q`` (rad; m for a prismatic joint): ``q ± eps`` rounded outward,
    ``(lo, hi)`` of ``q``'s shape (``eps`` the encoder error bound, broadcast)."""
    return I.sub(q, q, eps, eps)[0], I.add(q, q, eps, eps)[1]


class Backend(str, Enum):
    """Which implementation runs the step."""

    COMPILED = "compiled"
    NUMPY = "numpy"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True, eq=False)
class StepConfig:
    """What stays fixed during a run (build with :func:`configure`).

    Attributes
    ----------
    model : verifier.model.IntervalModel
    settings : TrackerSettings
        Validated (vectors of shape ``(n,)``).
    backend : Backend
    impl : StepImpl
        The implementation of the step ``backend`` names.
    const : verifier.constants.StepConstants
        The step's constants, rounded outward, read by name by both implementations.
    parallel : bool
        Compiled backend: spread the scenarios of a batch over
        ``NUMBA_NUM_THREADS`` thread slots (slot 0 on the calling thread, the
        others on a pool of Python threads, one kernel call each per block of
        samples).  Turn it off inside process pools or Dask workers;
        ``NUMBA_NUM_THREADS=1`` has the same effect.
    spread_hypotheses : bool
        Compiled backend, fewer scenarios than threads: spread the geometry
        hypotheses of every sample over the threads instead (one parallel
        region per sample).  Halves the time per sample on idle cores
        (benchmarks/README.md), but a thread that waits for a busy core costs
        a scheduler slice (milliseconds) at every sample: only for dedicated
        cores.  Results are the same in every case.
    """

    model: object
    settings: object
    backend: Backend
    impl: object
    const: StepConstants
    parallel: bool = True
    spread_hypotheses: bool = False

    @property
    def depth(self) -> int:
        """Samples kept in the window of past boxes."""
        return self.const.depth


def configure(model, settings, backend: str | Backend = Backend.COMPILED, *, parallel: bool = True,
              spread_hypotheses: bool = False) -> StepConfig:
    """Validate ``settings`` for ``model`` and derive the step's constants once
    (``parallel``, ``spread_hypotheses``: see :class:`StepConfig`)."""
    try:
        backend = Backend(backend)
    except ValueError:
        raise InputError(f"unknown backend {backend!r}: choose 'compiled' or 'numpy'") from None
    s = settings.validated(model.n)
    if s.xi_splits is not None and len(s.xi_splits) != model.m:
        raise InputError(f"xi_splits needs {model.m} counts (one per geometric parameter), got {len(s.xi_splits)}")
    return StepConfig(model=model, settings=s, backend=backend, impl=_IMPLS[backend], const=pack_constants(s, model.n),
                      parallel=bool(parallel), spread_hypotheses=bool(spread_hypotheses))


def partition_xi(XI, splits):
    """Split calibration boxes ``(B, m)`` into ``P = prod(splits)`` sub-boxes ``(B, P, m)``.

    Adjacent sub-boxes share the same float split point, so their union is
    exactly the original box.
    """
    lo, hi = (np.asarray(v, dtype=np.float64) for v in XI)
    B, m = lo.shape
    if splits is None or all(v == 1 for v in splits):
        return lo[:, None, :].copy(), hi[:, None, :].copy()
    points = []
    for i, cnt in enumerate(splits):
        inner = [lo[:, i] + (hi[:, i] - lo[:, i]) * (j / cnt) for j in range(1, cnt)]
        points.append(np.stack([lo[:, i]] + inner + [hi[:, i]], axis=1))  # (B, cnt + 1)
    combos = np.array(list(itertools.product(*(range(c) for c in splits))))  # (P, m)
    cols = np.arange(m)
    sub_lo = np.stack([np.stack([points[i][:, c[i]] for i in cols], axis=1) for c in combos], axis=1)
    sub_hi = np.stack([np.stack([points[i][:, c[i] + 1] for i in cols], axis=1) for c in combos], axis=1)
    return sub_lo, sub_hi


def init_state(config: StepConfig, x0, *, batch: int = 1, xi_box=None) -> TrackerState:
    """A fresh state before the first sample.

    Parameters
    ----------
    config : StepConfig
    x0 : (lo, hi)
        Initial pose boxes, arrays ``(batch, n)`` or ``(n,)``, m.
    batch : int
        Number of scenarios ``B``.
    xi_box : (lo, hi), optional
        Calibration box ``(m,)`` or ``(B, m)``; the robot's by default.
    """
    model, s = config.model, config.settings
    n, m, B, D = model.n, model.m, int(batch), config.depth
    XI = model.xi_box() if xi_box is None else xi_box
    XI = partition_xi((np.broadcast_to(XI[0], (B, m)), np.broadcast_to(XI[1], (B, m))), s.xi_splits)
    P = XI[0].shape[1]
    R = B * P
    lo = np.repeat(np.broadcast_to(np.asarray(x0[0], dtype=np.float64), (B, n)), P, axis=0)
    hi = np.repeat(np.broadcast_to(np.asarray(x0[1], dtype=np.float64), (B, n)), P, axis=0)
    xd0 = config.const.axis["xd0"]
    xd = np.stack([np.broadcast_to(-xd0, (R, n)), np.broadcast_to(xd0, (R, n))], axis=1)
    return TrackerState(
        batch=B, hypotheses=P, k=0,
        x=np.ascontiguousarray(np.stack([lo, hi], axis=1)),
        xd=np.ascontiguousarray(xd),
        xi=np.ascontiguousarray(np.stack([XI[0].reshape(R, m), XI[1].reshape(R, m)], axis=1)),
        q=np.zeros((R, 2, n)),
        past_x=np.zeros((R, D, 2, n)), past_q=np.zeros((R, D, 2, n)), past_r=np.zeros((R, D, n)),
        row_bad=np.full(R, -1, np.int64),
        init_mode=np.zeros(B, np.int64), mode=np.zeros(B, np.int64), streak=np.full(B, -1, np.int64),
        bad_at=np.full(B, -1, np.int64), max_width_pose=np.zeros(B), max_width_velocity=np.zeros(B),
        x_hull=np.zeros((B, 2, n)), xd_hull=np.zeros((B, 2, n)), qdd_hull=np.zeros((B, n)),
    )


class Event(str, Enum):
    """What a sample changed about the certified mode."""

    MODE_GAINED = "mode-gained"  # certified after a stretch without
    MODE_LOST = "mode-lost"  # no longer certified
    MODE_CHANGED = "mode-changed"  # certified, and the other mode than before
    INCONSISTENT = "inconsistent"  # no hypothesis survives: an assumption was violated

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class StepResult:
    """One scenario after one sample.

    Attributes
    ----------
    k : int
        Index of the sample.
    x, xd : (lo, hi) arrays (n,)
        Pose (m) and velocity (m/s) boxes (empty, ``lo > hi``, once inconsistent).
    mode : int
        Certified assembly mode, +1 / -1, or 0 (not certified).
    consistent : bool
        False from the sample where every hypothesis became empty on.
    events : tuple of Event
    """

    k: int
    x: tuple
    xd: tuple
    mode: int
    consistent: bool
    events: tuple = field(default=())


# ---------------------------------------------------------------------------- numpy reference


def _rows(a):
    return a[:, 0], a[:, 1]


def _numpy_step(config: StepConfig, st: TrackerState, qk, prior=None, const=None):
    model, c = config.model, config.const if const is None else const
    B, P, n, k = st.batch, st.hypotheses, model.n, st.k
    R, D = B * P, c.depth
    ax = c.axis
    qk = np.repeat(qk, P, axis=0)
    eps = ax["eps_q"]
    alive = st.row_bad < 0
    X, XD, XI = _rows(st.x), _rows(st.xd), _rows(st.xi)
    Q = reading_box(qk, eps)
    QDD = (np.full((R, n), -np.inf), np.full((R, n), np.inf))
    # from the boxes of the last sample: before the prediction replaces them
    vel = _VELOCITY[c.velocity_model]
    QDD, info = vel.info(model, c, st, qk, Q, X, XD, XI, QDD)
    if k > 0:
        # prediction (Taylor with Lagrange remainder)
        # a constant period is one float; an uneven recording's step an interval (verifier.clock)
        move = I.scale(c.step_lo, *XD) if c.step_lo == c.step_hi else I.mul(c.step_lo, c.step_hi, *XD)
        Xn = I.add(*I.add(*X, *move), ax["half_ts2_a_lo"], ax["half_ts2_a_hi"])
        XD = I.intersect(*I.add(*XD, ax["ts_a_lo"], ax["ts_a_hi"]), -ax["v_max"], ax["v_max"])
        X = Xn
    if prior is not None:
        # boxes known from elsewhere (the other passes of verifier.window) to hold the truth at this sample
        px, pxd = (np.repeat(np.asarray(a, dtype=np.float64), P, axis=0) for a in prior)
        X = I.intersect(*X, px[:, 0], px[:, 1])
        XD = I.intersect(*XD, pxd[:, 0], pxd[:, 1])
    # contraction to a fixpoint, row by row
    active = alive.copy()
    bad = st.row_bad.copy()
    for _ in range(c.max_iter):
        wx0 = I.width(*X).sum(-1)
        wv0 = I.width(*XD).sum(-1)
        Xc, Qc, XIc = hc4_pose(model, X, Q, XI)
        XIc = XIc if c.keep_xi else XI
        Xc = newton(model, Xc, Qc, XIc, "x")
        XDc = vel.contract(model, c, Xc, Qc, XIc, XD, info)
        keep = active[:, None]
        X, Q, XI, XD = ((np.where(keep, new[0], old[0]), np.where(keep, new[1], old[1]))
                        for new, old in ((Xc, X), (Qc, Q), (XIc, XI), (XDc, XD)))
        # ~(lo <= hi) also catches NaN bounds
        empty = active & (np.any(~(X[0] <= X[1]), -1) | np.any(~(XD[0] <= XD[1]), -1)
                          | np.any(~(XI[0] <= XI[1]), -1) | np.any(~(Q[0] <= Q[1]), -1))
        bad = np.where(empty, k, bad)
        active &= ~empty
        wx1 = I.width(*X).sum(-1)
        wv1 = I.width(*XD).sum(-1)
        gain = np.maximum((wx0 - wx1) / np.maximum(wx0, 1e-300),
                          np.where(np.isfinite(wv0), (wv0 - wv1) / np.maximum(wv0, 1e-300), 1.0))
        active &= gain > c.rel_tol
        if not active.any():
            break
    alive = bad < 0
    mode = mode_of(model, X, Q, XI).astype(np.int64)
    if c.split_boxes:
        narrow = np.all(X[1] - X[0] <= c.split_max_width, -1)  # also False for NaN/inf
        todo = np.nonzero(alive & (mode == 0) & narrow)[0]
        if todo.size:
            sub = lambda box: (box[0][todo], box[1][todo])  # noqa: E731
            (lo_t, hi_t), mode_t = split_prune(model, sub(X), sub(Q), sub(XI), max_pieces=c.split_boxes,
                                               tol=c.split_tol)
            X = (X[0].copy(), X[1].copy())
            X[0][todo], X[1][todo] = lo_t, hi_t
            mode[todo] = mode_t
            bad = np.where(alive & np.any(~(X[0] <= X[1]), -1), k, bad)
            alive = bad < 0
    mode = np.where(alive, mode, 0)
    # write the rows back; dead rows keep whatever they hold (never read again)
    st.x[:, 0], st.x[:, 1] = X
    st.xd[:, 0], st.xd[:, 1] = XD
    st.xi[:, 0], st.xi[:, 1] = XI
    st.q[:, 0], st.q[:, 1] = Q
    st.row_bad[:] = bad
    slot = k % D
    st.past_x[:, slot] = st.x
    st.past_q[:, slot] = st.q
    st.past_r[:, slot] = qk
    # combine the geometry hypotheses of each scenario
    _numpy_combine(st, alive, mode, QDD, k)


def _numpy_combine(st: TrackerState, alive, mode, QDD, k: int) -> None:
    """Combine the geometry hypotheses of each scenario at sample ``k``, in place (the numpy twin of the compiled
    ``combine``): the scenario's first inconsistent sample, its mode (the rows' common one, 0 if they differ),
    the hulls of its live rows' pose (m) and velocity (m/s) boxes and of their joint acceleration bounds
    ``QDD`` (joint units per s²), its certified streak and widest boxes.  ``alive`` ``(R,)`` and ``mode`` ``(R,)`` are
    the rows' after the step."""
    B, P, n = st.batch, st.hypotheses, st.x.shape[-1]
    live = alive.reshape(B, P)
    scen_alive = live.any(1)
    st.bad_at[:] = np.where(~scen_alive & (st.bad_at < 0), k, st.bad_at)
    rm = mode.reshape(B, P)
    mn = np.where(live, rm, 2).min(1)
    mx = np.where(live, rm, -2).max(1)
    new_mode = np.where(scen_alive & (mn == mx), mn, 0)
    lv = live[..., None]
    for src, dst in ((st.x, st.x_hull), (st.xd, st.xd_hull)):
        dst[:, 0] = np.where(lv, src[:, 0].reshape(B, P, n), np.inf).min(1)
        dst[:, 1] = np.where(lv, src[:, 1].reshape(B, P, n), -np.inf).max(1)
    qdd = np.maximum(np.abs(QDD[0]), np.abs(QDD[1])).reshape(B, P, n)
    st.qdd_hull[:] = np.where(lv, qdd, 0.0).max(1)
    if k == 0:
        st.init_mode[:] = new_mode
    st.streak[:] = np.where(new_mode != st.mode, k, st.streak)
    st.mode[:] = new_mode
    ok = st.bad_at < 0
    st.max_width_pose[:] = np.where(ok, np.maximum(st.max_width_pose, I.width(*_rows(st.x_hull)).max(-1)),
                                    st.max_width_pose)
    st.max_width_velocity[:] = np.where(ok, np.maximum(st.max_width_velocity,
                                                       I.width(*_rows(st.xd_hull)).max(-1)),
                                        st.max_width_velocity)


class VelocityInfo(Protocol):
    """The velocity information of one velocity model, in the reference (the compiled kernels mirror it with
    the strategies of :func:`verifier.compiled.step.velocity_strategy`)."""

    def info(self, model, c: StepConstants, st: TrackerState, qk, Q, X, XD, XI, QDD):
        """What the contraction needs at sample ``st.k``, from the boxes of sample ``k - 1`` (``X``, ``XD``,
        ``XI``: rows ``(lo, hi)``), the window of ``st``, the readings ``qk`` ``(R, n)`` and their box ``Q``:
        ``(QDD, info)``, the joint-acceleration bound (rad/s^2; ``QDD`` as given when none) and what
        :meth:`contract` reads."""

    def contract(self, model, c: StepConstants, X, Q, XI, XD, info):
        """The velocity box ``XD`` (m/s) contracted with ``info`` and the current boxes."""


class Displacement:
    """The ``SOUND`` model: mean joint rates over the displacement baselines, from past boxes and readings
    only (:func:`verifier.contractors.velocity_displacement`)."""

    def info(self, model, c, st, qk, Q, X, XD, XI, QDD):
        k, D = st.k, c.depth
        pasts = []
        for jb, base in enumerate(c.baseline):
            if base["j"] > min(k, D):
                break
            p = (k - base["j"]) % D
            qp = st.past_r[:, p]
            DQ = I.add(*I.sub(qk, qk, qp, qp), *c.diff_err[jb])
            pasts.append((_rows(st.past_x[:, p]), _rows(st.past_q[:, p]), DQ, (base["h_lo"], base["h_hi"])))
        return QDD, pasts

    def contract(self, model, c, X, Q, XI, XD, info):
        return velocity_displacement(model, X, Q, info, XI, XD, c.axis["a_max"])


class JointRates:
    """Finite differences of the last two readings: quantisation only (``PAPER``, unsound), or plus
    ``(t_s/2) [qdd]`` with ``with_qdd``, a joint-acceleration bound over the interval (``JOINT_FD``,
    :func:`_qdd_over_step`)."""

    def __init__(self, with_qdd: bool):
        self.with_qdd = with_qdd

    def info(self, model, c, st, qk, Q, X, XD, XI, QDD):
        k, ax = st.k, c.axis
        QD = (np.full_like(QDD[0], -np.inf), np.full_like(QDD[1], np.inf))
        if k > 0:
            prev = (k - 1) % c.depth
            if self.with_qdd:
                A = (np.broadcast_to(-ax["a_max"], QD[0].shape), np.broadcast_to(ax["a_max"], QD[0].shape))
                QDD = _qdd_over_step(model, c.step_hi, X, XD, _rows(st.past_q[:, prev]), Q, XI, A)
                if c.has_qdd_bound:
                    QDD = I.intersect(*QDD, -ax["qdd_bound"], ax["qdd_bound"])
            qp = st.past_r[:, prev]
            fd = I.div(*I.sub(qk, qk, qp, qp), c.step_lo, c.step_hi)
            QD = I.add(*fd, ax["quant_lo"], ax["quant_hi"])
            if self.with_qdd:
                # q_{k-1} = q_k - t_s qd_k + (t_s^2/2) qdd(zeta), per component, so
                # qd_k = FD + (t_s/2) qdd(zeta)
                QD = I.add(*QD, *I.mul(0.5 * c.step_lo, 0.5 * c.step_hi, *QDD))
                QD = (np.where(np.isnan(QD[0]), -np.inf, QD[0]), np.where(np.isnan(QD[1]), np.inf, QD[1]))
        return QDD, (QD if np.any(np.isfinite(QD[0])) else None)

    def contract(self, model, c, X, Q, XI, XD, info):
        return XD if info is None else velocity(model, X, Q, XI, XD, info)


#: The reference's strategy of each velocity model (by its code in :class:`StepConstants`).
_VELOCITY = {SOUND: Displacement(), PAPER: JointRates(with_qdd=False), JOINT_FD: JointRates(with_qdd=True)}


def _qdd_over_step(model, ts, X, XD, Q_prev, Q_now, XI, A):
    """Bound ``|qdd|`` over ``[t_k, t_{k+1}]`` from the boxes at ``t_k``.

    Over the interval, ``x`` lies in ``[x]_k + [0, t_s][xd]_k + [0, t_s^2/2][a]``
    and ``xd`` in ``[xd]_k + [0, t_s][a]``.  The joints are enclosed by Newton
    on ``f = 0`` in ``q`` from a generous box around both samples; because the
    joint path is continuous and always solves ``f = 0``, it cannot leave that
    box if the contracted result lies strictly inside it.  Then
    ``qd = -J_q^{-1} J_x xd`` and ``qdd = -J_q^{-1}(J_x xdd + h)`` are enclosed
    by :func:`linear_enclosure`.  Returns ``(lo, hi)`` of ``qdd`` (``-inf, inf``
    where no bound could be proved); ``ts`` the step's upper bound, s.
    """
    Xs = I.add(*X, *I.mul(0.0, ts, *XD))
    half_ts2 = I.scale(0.5, *I.mul(ts, ts, ts, ts))  # t_s^2 / 2, rounded outward
    Xs = I.add(*Xs, *I.mul(*I.hull(0.0, 0.0, *half_ts2), *A))
    XDs = I.add(*XD, *I.mul(0.0, ts, *A))
    ql, qh = I.hull(*Q_prev, *Q_now)
    margin = 0.05  # rad; the result must land strictly inside this box
    Q0 = (ql - margin, qh + margin)
    Qs = Q0
    for _ in range(3):
        Qs = newton(model, Xs, Qs, XI, "q")
        Qs = (np.where(Qs[0] > Qs[1], Q0[0], Qs[0]), np.where(Qs[0] > Qs[1], Q0[1], Qs[1]))
    inside = np.all((Qs[0] > Q0[0]) & (Qs[1] < Q0[1]), axis=-1)
    Jq = model.tape_jq.evaluate([Xs, Qs, XI])[0]
    R = model.tape_jx_xd.evaluate([Xs, Qs, XI, XDs])[0]
    QDs = linear_enclosure(*Jq, -R[1], -R[0])
    R2 = model.tape_accel_rhs.evaluate([Xs, Qs, XI, XDs, QDs, A])[0]
    QDD = linear_enclosure(*Jq, -R2[1], -R2[0])
    ok = inside[:, None] & np.isfinite(QDD[0]) & np.isfinite(QDD[1]) & ~(QDD[0] > QDD[1])
    return np.where(ok, QDD[0], -np.inf), np.where(ok, QDD[1], np.inf)


# ---------------------------------------------------------------------------- the two implementations


class StepImpl(Protocol):
    """What an implementation of the step provides (:class:`NumpyStep` here, its twin
    :class:`verifier.compiled.driver.CompiledStep` beside the kernels)."""

    def advance(self, config: StepConfig, state: TrackerState, q, record=None, prior=None, const=None) -> None:
        """Advance ``state`` over checked readings ``q`` ``(B, Kc, n)`` (see :func:`advance`), with the step's
        constants ``const`` (``config.const`` when None)."""

    def pose_solutions(self, model, Q, XI, X_search, tol: float, small: float, max_boxes: int, sweeps: int):
        """See :func:`pose_solution_arrays`."""


class NumpyStep:
    """The reference: the step vectorised over rows with numpy, one sample at a time."""

    def advance(self, config, state, q, record=None, prior=None, const=None):
        for kk in range(q.shape[1]):
            with I.quiet_fp():
                _numpy_step(config, state, q[:, kk], None if prior is None else (prior[0][:, kk], prior[1][:, kk]),
                            const)
            if record is not None:
                record[0][:, kk] = state.x_hull
                record[1][:, kk] = state.xd_hull
                record[2][:, kk] = state.mode
                record[3][:, kk] = state.qdd_hull
            state.k += 1

    def pose_solutions(self, model, Q, XI, X_search, tol, small, max_boxes, sweeps):
        sols = _np_pose_solutions(model, Q, XI, X_search, tol=tol, small=small, max_boxes=max_boxes, sweeps=sweeps)
        if sols is None:
            return None
        boxes = np.array([np.stack(b) for b, _ in sols], dtype=np.float64).reshape(-1, 2, model.n)
        return boxes, np.array([m for _, m in sols], dtype=np.int64)


_IMPLS = {Backend.NUMPY: NumpyStep(), Backend.COMPILED: CompiledStep()}


def pose_solution_arrays(model, Q, XI, X_search, *, tol: float = 1e-7, small: float = 5e-3,
                         max_boxes: int = 20000, sweeps: int = 30, backend: str | Backend = Backend.COMPILED):
    """Enclose every forward-kinematics solution in ``X_search`` (the branch and prune of
    :func:`verifier.contractors.pose_solutions`, same arguments) run by ``backend``: the solution
    boxes ``(N, 2, n)`` (m) and their modes ``(N,)`` (0: undecided), or ``None`` when the budget of
    ``max_boxes`` boxes ran out."""
    return _IMPLS[Backend(backend)].pose_solutions(model, Q, XI, X_search, tol, small, max_boxes, sweeps)


def pose_solutions(model, Q, XI, X_search, *, tol: float = 1e-7, small: float = 5e-3, max_boxes: int = 20000,
                   sweeps: int = 30, backend: str | Backend = Backend.COMPILED):
    """:func:`pose_solution_arrays` as the reference returns it: a list of ``((lo, hi), mode)``, or ``None``."""
    got = pose_solution_arrays(model, Q, XI, X_search, tol=tol, small=small, max_boxes=max_boxes, sweeps=sweeps,
                               backend=backend)
    if got is None:
        return None
    boxes, modes = got
    return [((boxes[i, 0].copy(), boxes[i, 1].copy()), int(modes[i])) for i in range(len(modes))]


def kernel_array(a, dtype=np.float64):
    """``a`` as a C-contiguous, writable array of ``dtype`` (copied only when it is not one already): one
    kernel signature whatever the caller's array (a row of a frozen recording, or a broadcast, is read-only;
    the kernels only read these arrays)."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return a if a.flags.writeable else a.copy()


def checked_sample(config: StepConfig, state: TrackerState, q):
    """Readings ``q`` of one sample as the kernels take them ``(B, 1, n)``, or :class:`InputError` for a
    reading of the wrong shape or not finite."""
    q = np.asarray(q, dtype=np.float64)
    if q.shape != (state.batch, config.model.n) or not np.isfinite(q).all():
        raise InputError(f"sample {state.k}: expected {state.batch}x{config.model.n} finite joint values, "
                         f"got shape {q.shape}")
    return kernel_array(q[:, None, :])


def step(config: StepConfig, state: TrackerState, q, const=None) -> None:
    """Advance ``state`` by one sample of readings ``q`` ``(B, n)``, rad, in place, with the step's constants
    ``const`` (``config.const`` when None: a step of ``t_s``).

    The new boxes, modes and widths are in ``state`` (``x_hull``, ``xd_hull``,
    ``mode``, ...).  Raises :class:`InputError` for a reading of the wrong
    shape or not finite (the state is then unchanged).
    """
    config.impl.advance(config, state, checked_sample(config, state, q), None, None, const)


def advance(config: StepConfig, state: TrackerState, q, record=None, prior=None, clock=None) -> None:
    """Advance ``state`` over a block of readings ``q`` ``(B, Kc, n)``.

    The compiled backend runs the whole block in one kernel call, scenarios in
    parallel when there are several; ``record`` (arrays ``x (B, Kc, 2, n)``,
    ``xd (B, Kc, 2, n)``, ``mode (B, Kc)``, ``qdd (B, Kc, n)``), when given,
    receives every sample's boxes.  ``prior`` (arrays ``x (B, Kc, 2, n)``,
    ``xd (B, Kc, 2, n)``), when given, are boxes known to hold the true pose
    (m) and velocity (m/s) at each sample: they are intersected with the
    predicted boxes before the contraction (the passes of
    :mod:`verifier.window`; an infinite box leaves a sample unconstrained).
    ``clock`` (a :class:`verifier.clock.SampleClock` of the samples from the
    state's first, or None for the constant period ``t_s``) gives each sample
    the constants of its own steps; runs of samples whose steps are one
    period each go through in one call as without it.
    """
    q = np.asarray(q, dtype=np.float64)
    B, Kc = state.batch, q.shape[1]
    if q.shape != (B, Kc, config.model.n) or not np.all(np.isfinite(q)):
        bad = np.nonzero(~np.all(np.isfinite(q.reshape(B, Kc, -1)), axis=(0, 2)))[0] if q.ndim == 3 else []
        k = state.k + (int(bad[0]) if len(bad) else 0)
        raise InputError(f"sample {k}: expected {B}x{config.model.n} finite joint values, got shape {q.shape[::2]}")
    if prior is not None:
        prior = tuple(kernel_array(a) for a in prior)
        if any(a.shape != (B, Kc, 2, config.model.n) for a in prior):
            raise InputError(f"prior boxes must have shape ({B}, {Kc}, 2, {config.model.n})")
    if clock is None:
        config.impl.advance(config, state, kernel_array(q), record, prior)
        return
    consts = [clock.constants(config.const, config.settings, state.k + i) for i in range(Kc)]
    start = 0
    while start < Kc:
        const, stop = consts[start], start + 1
        while stop < Kc and const is config.const and consts[stop] is const:
            stop += 1  # one call for a run of one-period steps
        part = slice(start, stop)
        rec = None if record is None else tuple(np.empty(a[:, part].shape, a.dtype) for a in record)
        pri = None if prior is None else tuple(kernel_array(a[:, part]) for a in prior)
        config.impl.advance(config, state, kernel_array(q[:, part]), rec, pri, const)
        if record is not None:
            for a, r in zip(record, rec):
                a[:, part] = r
        start = stop
