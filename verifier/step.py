"""The tracker as an immutable configuration, a mutable state and one step.

Following the model/data split of pinocchio: a :class:`StepConfig` (the
interval model, validated settings and the constants derived from them, the
backend) never changes during a run; a :class:`TrackerState` holds everything
that does (boxes of every geometry hypothesis, the window of past boxes and
readings the velocity baselines use, mode streaks, inconsistencies); and
:func:`step` advances the state by one sample.  :class:`Tracker` bundles one
of each for online use (``update(q)``); :func:`verifier.tracker.track` and
:func:`verifier.tracker.track_batch` are loops over the same step.

Two backends compute the same step:

* ``"compiled"`` (default): numba kernels (:mod:`verifier.compiled`), no
  Python per operation; scenarios in parallel for batches;
* ``"numpy"``: the reference, vectorised over rows with numpy.

Both follow the same float operations; their boxes agree bit for bit except
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

import numpy as np

from . import interval as I
from .contractors import hc4_pose, mode_of, newton, split_prune, velocity, velocity_displacement
from .contractors import pose_solutions as _np_pose_solutions
from crosscert.robots.errors import InputError
from .linalg import linear_enclosure

__all__ = ["Backend", "StepConfig", "TrackerState", "StepResult", "Event", "configure", "init_state", "partition_xi", "step",
           "advance", "Tracker", "pose_solutions"]


class Backend(str, Enum):
    """Which implementation runs the step."""

    COMPILED = "compiled"
    NUMPY = "numpy"

    def __str__(self) -> str:
        return self.value


_VMODEL_CODE = {"sound": 0, "joint-fd": 1, "paper": 2}


@dataclass(frozen=True, eq=False)
class StepConfig:
    """What stays fixed during a run (build with :func:`configure`).

    Attributes
    ----------
    model : verifier.model.IntervalModel
    settings : TrackerSettings
        Validated (vectors of shape ``(n,)``).
    backend : Backend
    fpar, ipar, vec, base, diff_err, h : arrays
        Constants of the step: floats, integers, per-axis vectors (see
        :mod:`verifier.compiled.step` for the layout), baselines ``j``
        ``(J,)``, the error interval of a reading difference ``j`` samples
        apart ``(J, 2, n)`` rad, and ``h = j t_s`` ``(J, 2)`` s, all rounded
        outward.
    depth : int
        Samples kept in the window of past boxes.
    parallel : bool
        Compiled backend: spread the scenarios of a batch over numba's
        threads (one parallel region per block of samples).  Turn it off
        inside process pools or Dask workers; ``NUMBA_NUM_THREADS=1`` has the
        same effect.
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
    fpar: np.ndarray
    ipar: np.ndarray
    vec: np.ndarray
    base: np.ndarray
    diff_err: np.ndarray
    h: np.ndarray
    depth: int
    parallel: bool = True
    spread_hypotheses: bool = False


def _difference_error(s, j: int, two_eps):
    """Error interval of a difference of two readings ``j`` samples apart, rad (outward)."""
    if s.eps_q_fast is None:
        return two_eps
    two_fast = I.scale(2.0, -s.eps_q_fast, s.eps_q_fast)[1]
    span = I.mul(float(j), float(j), s.t_s, s.t_s)[1]  # j t_s, rounded up
    bound = I.add(two_fast, two_fast, *I.mul(span, span, s.drift_rate, s.drift_rate))[1]
    bound = np.minimum(bound, two_eps[1])
    return -bound, bound


def configure(model, settings, backend: str | Backend = Backend.COMPILED, *, parallel: bool = True,
              spread_hypotheses: bool = False) -> StepConfig:
    """Validate ``settings`` for ``model`` and derive the step's constants once
    (``parallel``, ``spread_hypotheses``: see :class:`StepConfig`)."""
    from .settings import VelocityModel

    try:
        backend = Backend(backend)
    except ValueError:
        raise InputError(f"unknown backend {backend!r}: choose 'compiled' or 'numpy'") from None
    s = settings.validated(model.n)
    n, ts = model.n, s.t_s
    A = (-s.a_max, s.a_max)
    with I.quiet_fp():
        half_ts2_A = I.mul(*I.scale(0.5, *I.mul(ts, ts, ts, ts)), *A)  # (t_s^2 / 2) [a], outward
        ts_A = I.scale(ts, *A)
        two_eps = I.scale(2.0, -s.eps_q, s.eps_q)
        quant = I.div(*two_eps, ts, ts)  # 2 eps / t_s
        diff = np.array([np.stack(_difference_error(s, j, two_eps)) for j in s.baselines]).reshape(-1, 2, n)
        h = np.array([np.stack(I.mul(float(j), float(j), ts, ts)) for j in s.baselines]).reshape(-1, 2)
    qdd = np.full(n, np.inf) if s.qdd_bound is None else s.qdd_bound
    vec = np.stack([s.eps_q, s.a_max, s.v_max, half_ts2_A[0], half_ts2_A[1], ts_A[0], ts_A[1],
                    quant[0], quant[1], qdd]).astype(np.float64)
    sound = s.velocity_model is VelocityModel.SOUND
    P = int(np.prod(s.xi_splits)) if s.xi_splits is not None else 1
    if s.xi_splits is not None and len(s.xi_splits) != model.m:
        raise InputError(f"xi_splits needs {model.m} counts (one per geometric parameter), got {len(s.xi_splits)}")
    fpar = np.array([ts, s.rel_tol, s.split_tol, s.split_max_width], np.float64)
    ipar = np.array([_VMODEL_CODE[s.velocity_model.value], int(s.max_iter), int(s.split_boxes), int(bool(s.keep_xi)),
                     P, int(s.qdd_bound is not None), 0, 0], np.int64)
    return StepConfig(model=model, settings=s, backend=backend, fpar=fpar, ipar=ipar, vec=vec,
                      base=np.array(s.baselines, np.int64), diff_err=np.ascontiguousarray(diff), h=h,
                      depth=max(s.baselines) if sound else 1, parallel=bool(parallel),
                      spread_hypotheses=bool(spread_hypotheses))


@dataclass(eq=False)
class TrackerState:
    """Everything a run changes, for ``B`` scenarios of ``P`` geometry hypotheses.

    Row arrays (``R = B P`` rows): ``x``, ``xd`` ``(R, 2, n)`` pose (m) and
    velocity (m/s) boxes, row 0 lower and row 1 upper bounds; ``xi``
    ``(R, 2, m)`` calibration sub-box; ``q`` ``(R, 2, n)`` joint box of the
    last sample, rad; ``past_x``, ``past_q`` ``(R, D, 2, n)`` and ``past_r``
    ``(R, D, n)``: boxes and readings of the last ``D`` samples (slot
    ``k mod D``); ``row_bad`` ``(R,)`` sample at which the hypothesis became
    empty (-1: consistent).

    Scenario arrays (``B``): ``init_mode``, ``mode`` (certified mode at the
    first / last sample, 0 = not certified), ``streak`` (sample since which
    ``mode`` holds), ``bad_at`` (first sample with no consistent hypothesis,
    -1 none), ``max_width_pose``, ``max_width_velocity`` (m, m/s), ``x_hull``,
    ``xd_hull`` ``(B, 2, n)`` the boxes of the last sample, ``qdd_hull``
    ``(B, n)`` the joint-acceleration bound used (rad/s^2, ``inf`` none).
    ``k`` counts the samples consumed.
    """

    batch: int
    hypotheses: int
    k: int
    x: np.ndarray
    xd: np.ndarray
    xi: np.ndarray
    q: np.ndarray
    past_x: np.ndarray
    past_q: np.ndarray
    past_r: np.ndarray
    row_bad: np.ndarray
    init_mode: np.ndarray
    mode: np.ndarray
    streak: np.ndarray
    bad_at: np.ndarray
    max_width_pose: np.ndarray
    max_width_velocity: np.ndarray
    x_hull: np.ndarray
    xd_hull: np.ndarray
    qdd_hull: np.ndarray


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
    xd = np.stack([np.broadcast_to(-s.xd0, (R, n)), np.broadcast_to(s.xd0, (R, n))], axis=1)
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


def _numpy_step(config: StepConfig, st: TrackerState, qk, prior=None):
    model, s = config.model, config.settings
    B, P, n, k = st.batch, st.hypotheses, model.n, st.k
    R, D = B * P, config.depth
    ts = s.t_s
    vec = config.vec
    vmodel = int(config.ipar[0])
    qk = np.repeat(qk, P, axis=0)
    eps = vec[0]
    alive = st.row_bad < 0
    X, XD, XI = _rows(st.x), _rows(st.xd), _rows(st.xi)
    Q = (I.sub(qk, qk, eps, eps)[0], I.add(qk, qk, eps, eps)[1])
    QDD = (np.full((R, n), -np.inf), np.full((R, n), np.inf))
    QD = (np.full((R, n), -np.inf), np.full((R, n), np.inf))
    prev = (k - 1) % D
    if k > 0 and vmodel != 0:
        if vmodel == 1:
            A = (np.broadcast_to(-s.a_max, (R, n)), np.broadcast_to(s.a_max, (R, n)))
            QDD = _qdd_over_step(model, s, X, XD, _rows(st.past_q[:, prev]), Q, XI, A)
            if s.qdd_bound is not None:
                QDD = I.intersect(*QDD, -s.qdd_bound, s.qdd_bound)
        qp = st.past_r[:, prev]
        fd = I.div(*I.sub(qk, qk, qp, qp), ts, ts)
        QD = I.add(*fd, vec[7], vec[8])
        if vmodel == 1:
            # q_{k-1} = q_k - t_s qd_k + (t_s^2/2) qdd(zeta), per component, so
            # qd_k = FD + (t_s/2) qdd(zeta)
            QD = I.add(*QD, *I.mul(0.5 * ts, 0.5 * ts, *QDD))
            QD = (np.where(np.isnan(QD[0]), -np.inf, QD[0]), np.where(np.isnan(QD[1]), np.inf, QD[1]))
    if k > 0:
        # prediction (Taylor with Lagrange remainder)
        Xn = I.add(*I.add(*X, *I.scale(ts, *XD)), vec[3], vec[4])
        XD = I.intersect(*I.add(*XD, vec[5], vec[6]), -vec[2], vec[2])
        X = Xn
    if prior is not None:
        # boxes known from elsewhere (the other passes of verifier.window) to hold the truth at this sample
        px, pxd = (np.repeat(np.asarray(a, dtype=np.float64), P, axis=0) for a in prior)
        X = I.intersect(*X, px[:, 0], px[:, 1])
        XD = I.intersect(*XD, pxd[:, 0], pxd[:, 1])
    # the displacement baselines depend only on past boxes and readings
    pasts = []
    if vmodel == 0:
        for jb, j in enumerate(config.base):
            if j > min(k, D):
                break
            p = (k - j) % D
            qp = st.past_r[:, p]
            DQ = I.add(*I.sub(qk, qk, qp, qp), *config.diff_err[jb])
            pasts.append((_rows(st.past_x[:, p]), _rows(st.past_q[:, p]), DQ, tuple(config.h[jb])))
    # contraction to a fixpoint, row by row
    active = alive.copy()
    bad = st.row_bad.copy()
    has_qd = np.any(np.isfinite(QD[0]))
    for _ in range(s.max_iter):
        wx0 = I.width(*X).sum(-1)
        wv0 = I.width(*XD).sum(-1)
        Xc, Qc, XIc = hc4_pose(model, X, Q, XI)
        XIc = XIc if s.keep_xi else XI
        Xc = newton(model, Xc, Qc, XIc, "x")
        if vmodel == 0:
            XDc = velocity_displacement(model, Xc, Qc, pasts, XIc, XD, s.a_max)
        elif has_qd:
            XDc = velocity(model, Xc, Qc, XIc, XD, QD)
        else:
            XDc = XD
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
        active &= gain > s.rel_tol
        if not active.any():
            break
    alive = bad < 0
    mode = mode_of(model, X, Q, XI).astype(np.int64)
    if s.split_boxes:
        narrow = np.all(X[1] - X[0] <= s.split_max_width, -1)  # also False for NaN/inf
        todo = np.nonzero(alive & (mode == 0) & narrow)[0]
        if todo.size:
            sub = lambda box: (box[0][todo], box[1][todo])  # noqa: E731
            (lo_t, hi_t), mode_t = split_prune(model, sub(X), sub(Q), sub(XI), max_pieces=s.split_boxes,
                                               tol=s.split_tol)
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


def _qdd_over_step(model, s, X, XD, Q_prev, Q_now, XI, A):
    """Bound ``|qdd|`` over ``[t_k, t_{k+1}]`` from the boxes at ``t_k``.

    Over the interval, ``x`` lies in ``[x]_k + [0, t_s][xd]_k + [0, t_s^2/2][a]``
    and ``xd`` in ``[xd]_k + [0, t_s][a]``.  The joints are enclosed by Newton
    on ``f = 0`` in ``q`` from a generous box around both samples; because the
    joint path is continuous and always solves ``f = 0``, it cannot leave that
    box if the contracted result lies strictly inside it.  Then
    ``qd = -J_q^{-1} J_x xd`` and ``qdd = -J_q^{-1}(J_x xdd + h)`` are enclosed
    by :func:`linear_enclosure`.  Returns ``(lo, hi)`` of ``qdd`` (``-inf, inf``
    where no bound could be proved).
    """
    ts = s.t_s
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


# ---------------------------------------------------------------------------- compiled


def _empty_record(B, n):
    return np.zeros((B, 0, 2, n)), np.zeros((B, 0, 2, n)), np.zeros((B, 0), np.int64), np.zeros((B, 0, n))


def _compiled_steps(config: StepConfig, st: TrackerState, q, record=None, prior=None):
    """Advance the state over readings ``q`` ``(B, Kc, n)`` in one kernel call,
    threaded as ``config`` says."""
    from .compiled import step as kernels

    prog = config.model.program
    B, n = st.batch, config.model.n
    ipar = config.ipar
    if record is None:
        rec = _empty_record(B, n)
    else:
        ipar = ipar.copy()
        ipar[6] = 1
        rec = record
    if prior is None:
        prior = (np.zeros((B, 0, 2, n)), np.zeros((B, 0, 2, n)))
    else:
        ipar = ipar.copy()
        ipar[7] = 1
    import numba

    threads = numba.config.NUMBA_NUM_THREADS
    if threads > 1 and config.spread_hypotheses and st.batch < threads and st.hypotheses > 1:
        run = kernels.run_hypotheses_parallel
    elif threads > 1 and config.parallel and st.batch > 1:
        run = kernels.run_parallel
    else:
        run = kernels.run_serial
    run(prog.code, prog.value, prog.outs, prog.meta, prog.n_nodes, st.k, q, st.x, st.xd, st.xi, st.q,
        st.past_x, st.past_q, st.past_r, st.row_bad, st.init_mode, st.mode, st.streak, st.bad_at,
        st.max_width_pose, st.max_width_velocity, st.x_hull, st.xd_hull, st.qdd_hull,
        config.fpar, ipar, config.vec, config.base, config.diff_err, config.h, *rec, *prior)
    st.k += q.shape[1]


def pose_solutions(model, Q, XI, X_search, *, tol: float = 1e-7, small: float = 5e-3, max_boxes: int = 20000,
                   sweeps: int = 30, backend: str | Backend = Backend.COMPILED):
    """Enclose every forward-kinematics solution in ``X_search``: the branch
    and prune of :func:`verifier.contractors.pose_solutions` (same arguments
    and result) run by ``backend``."""
    if Backend(backend) is Backend.NUMPY:
        return _np_pose_solutions(model, Q, XI, X_search, tol=tol, small=small, max_boxes=max_boxes, sweeps=sweeps)
    from .compiled.contractors import pose_solutions as kernel

    prog = model.program
    box = lambda b: np.ascontiguousarray(np.stack([np.asarray(b[0], float), np.asarray(b[1], float)]))  # noqa: E731
    out = np.empty((max_boxes, 2, model.n))
    modes = np.empty(max_boxes, np.int64)
    count = kernel(prog.code, prog.value, prog.outs, prog.meta, prog.n_nodes, box(Q), box(XI), box(X_search),
                   float(tol), float(small), int(max_boxes), int(sweeps), out, modes)
    if count < 0:
        return None
    return [((out[i, 0].copy(), out[i, 1].copy()), int(modes[i])) for i in range(count)]


def _kernel_array(a):
    """A writable C-contiguous float64 copy: numba compiles a separate kernel for
    each array layout and for read-only arrays (a row of a frozen recording
    would cost a second compilation)."""
    return np.array(a, dtype=np.float64, order="C", copy=True)


def _check_sample(config, st, q):
    q = np.asarray(q, dtype=np.float64)
    if q.shape != (st.batch, config.model.n) or not np.all(np.isfinite(q)):
        raise InputError(f"sample {st.k}: expected {st.batch}x{config.model.n} finite joint values, got shape {q.shape}")
    return q


def step(config: StepConfig, state: TrackerState, q) -> None:
    """Advance ``state`` by one sample of readings ``q`` ``(B, n)``, rad, in place.

    The new boxes, modes and widths are in ``state`` (``x_hull``, ``xd_hull``,
    ``mode``, ...).  Raises :class:`InputError` for a reading of the wrong
    shape or not finite (the state is then unchanged).
    """
    q = _check_sample(config, state, q)
    if config.backend is Backend.NUMPY:
        with I.quiet_fp():
            _numpy_step(config, state, q)
        state.k += 1
    else:
        _compiled_steps(config, state, _kernel_array(q[:, None, :]))


def advance(config: StepConfig, state: TrackerState, q, record=None, prior=None) -> None:
    """Advance ``state`` over a block of readings ``q`` ``(B, Kc, n)``.

    The compiled backend runs the whole block in one kernel call, scenarios in
    parallel when there are several; ``record`` (arrays ``x (B, Kc, 2, n)``,
    ``xd (B, Kc, 2, n)``, ``mode (B, Kc)``, ``qdd (B, Kc, n)``), when given,
    receives every sample's boxes.  ``prior`` (arrays ``x (B, Kc, 2, n)``,
    ``xd (B, Kc, 2, n)``), when given, are boxes known to hold the true pose
    (m) and velocity (m/s) at each sample: they are intersected with the
    predicted boxes before the contraction (the passes of
    :mod:`verifier.window`; an infinite box leaves a sample unconstrained).
    """
    q = np.asarray(q, dtype=np.float64)
    B, Kc = state.batch, q.shape[1]
    if q.shape != (B, Kc, config.model.n) or not np.all(np.isfinite(q)):
        bad = np.nonzero(~np.all(np.isfinite(q.reshape(B, Kc, -1)), axis=(0, 2)))[0] if q.ndim == 3 else []
        k = state.k + (int(bad[0]) if len(bad) else 0)
        raise InputError(f"sample {k}: expected {B}x{config.model.n} finite joint values, got shape {q.shape[::2]}")
    if prior is not None:
        prior = tuple(_kernel_array(a) for a in prior)
        if any(a.shape != (B, Kc, 2, config.model.n) for a in prior):
            raise InputError(f"prior boxes must have shape ({B}, {Kc}, 2, {config.model.n})")
    if config.backend is Backend.COMPILED:
        _compiled_steps(config, state, _kernel_array(q), record, prior)
        return
    for kk in range(Kc):
        with I.quiet_fp():
            _numpy_step(config, state, q[:, kk], None if prior is None else (prior[0][:, kk], prior[1][:, kk]))
        if record is not None:
            record[0][:, kk] = state.x_hull
            record[1][:, kk] = state.xd_hull
            record[2][:, kk] = state.mode
            record[3][:, kk] = state.qdd_hull
        state.k += 1


class Tracker:
    """Online tracker of one scenario: feed it one reading at a time.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    settings : TrackerSettings
    x0 : (lo, hi)
        Initial pose box ``(n,)``, m.
    xi_box : (lo, hi), optional
        Calibration box, the robot's by default.
    backend : {"compiled", "numpy"}
    spread_hypotheses : bool
        Spread the hypotheses of each sample over numba's threads: lower
        latency on dedicated cores, erratic on busy ones (see :class:`StepConfig`).

    Examples
    --------
    >>> tr = Tracker(model, settings, x0)          # doctest: +SKIP
    >>> r = tr.update(q)                            # q: (n,) rad
    >>> r.mode, r.x, r.events                       # doctest: +SKIP
    """

    def __init__(self, model, settings, x0, *, xi_box=None, backend: str | Backend = Backend.COMPILED,
                 spread_hypotheses: bool = False):
        self.config = configure(model, settings, backend, spread_hypotheses=spread_hypotheses)
        self.state = init_state(self.config, x0, batch=1, xi_box=xi_box)
        self._mode = 0
        self._consistent = True

    def update(self, q) -> StepResult:
        """Advance by one reading ``q`` ``(n,)``, rad; returns the new boxes and events."""
        st = self.state
        step(self.config, st, np.asarray(q, dtype=np.float64).reshape(1, -1))
        k = st.k - 1
        mode = int(st.mode[0])
        consistent = bool(st.bad_at[0] < 0)
        events = []
        if not consistent and self._consistent:
            events.append(Event.INCONSISTENT)
        elif consistent:
            if mode != self._mode:
                if self._mode == 0:
                    events.append(Event.MODE_GAINED)
                elif mode == 0:
                    events.append(Event.MODE_LOST)
                else:
                    events.append(Event.MODE_CHANGED)
        self._mode, self._consistent = mode, consistent
        return StepResult(k=k, x=(st.x_hull[0, 0].copy(), st.x_hull[0, 1].copy()),
                          xd=(st.xd_hull[0, 0].copy(), st.xd_hull[0, 1].copy()), mode=mode,
                          consistent=consistent, events=tuple(events))
