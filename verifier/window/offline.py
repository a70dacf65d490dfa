"""The offline window: :func:`track_window`, the verdict of a whole recording."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError

from ..one_motion import ONE_MOTION_SAMPLES
from ..settings import TrackerSettings, Verdict
from ..step import Backend, configure, partition_xi
from ..tracker import initial_box_from_mode, verdict_of
from .explain import Explainer, ExplainRequest
from .hypotheses import Hypothesis, decide
from .passes import FinalBoxes, Passes, run_pass, tube_hull
from .results import HypothesisResult, HypothesisStatus, Refutation, VerdictReason, WindowResult

__all__ = ["track_window", "WindowStart", "WINDOW_MAX_PASSES", "WINDOW_MAX_GEOMETRIES", "WINDOW_REL_TOL"]

#: Default pass budget of a round (backward and forward passes alternate).
WINDOW_MAX_PASSES = 6
#: Default budget of geometry sub-boxes per hypothesis (halving surviving ones between rounds).
WINDOW_MAX_GEOMETRIES = 64
#: Default resolution (m) of the enumeration of the last reading's poses (the hypotheses' final boxes).
WINDOW_FK_TOL = 1e-5
#: Passes stop once the summed tube widths shrink by less than this fraction in a pass.
WINDOW_REL_TOL = 0.02


#: The verdicts a window can be asked about (``track_window(goal=...)``).
_GOALS = (Verdict.MODE_CHANGED, Verdict.MODE_UNCHANGED)


def _goal(goal):
    """``goal`` as a :class:`Verdict` of :data:`_GOALS`, or ``None``."""
    if goal is None:
        return None
    try:
        verdict = Verdict(goal)
    except ValueError:
        verdict = None
    if verdict not in _GOALS:
        raise InputError(f"goal must be one of {[g.value for g in _GOALS]} or None, got {goal!r}")
    return verdict


def _targets(hyps, m0, goal):
    """The hypotheses whose refutation can give the verdict ``goal`` (all of them when ``goal`` is ``None``):
    ``MODE_CHANGED`` is reached only by refuting the initial mode ``m0``, ``MODE_UNCHANGED`` only by refuting
    the other one."""
    if goal is None:
        return list(hyps)
    return [h for h in hyps if (h.m == m0) == (goal is Verdict.MODE_CHANGED)]


@dataclass(frozen=True, eq=False)
class WindowStart:
    """The rows a window starts from, with what is known at its first sample: a tracker's state there.

    A window that starts in the middle of a motion (the online anchor,
    :class:`~verifier.window.online.OnlineMonitor`) starts from the tracker's
    rows at that sample: each geometry sub-box with its own pose and velocity
    box.  The tracker's boxes hold the truth under its assumptions, so the
    window's first forward pass may start from them (its initial velocity is
    this box, not the settings' ``xd0``).

    Attributes
    ----------
    xi_lo, xi_hi : ndarray, shape (R, m)
        Geometry sub-boxes of the rows.
    x, xd : ndarray, shape (R, 2, n)
        Pose (m) and velocity (m/s) boxes of each row at the first sample, lower bounds in ``[:, 0]``.
    mode : int
        Assembly mode known at the first sample (+1 / -1; a window's decision there), or 0: the mode the
        boxes certify, if any.
    """

    xi_lo: np.ndarray = field(repr=False)
    xi_hi: np.ndarray = field(repr=False)
    x: np.ndarray = field(repr=False)
    xd: np.ndarray = field(repr=False)
    mode: int = 0

    @property
    def rows(self) -> int:
        return int(self.xi_lo.shape[0])


def _start_prior(start: WindowStart, K: int):
    """Prior tubes ``(R, K, 2, n)`` holding the start's boxes at the first sample and nothing after."""
    R, n = start.x.shape[0], start.x.shape[2]
    x = np.empty((R, K, 2, n))
    x[:, :, 0], x[:, :, 1] = -np.inf, np.inf
    xd = x.copy()
    x[:, 0], xd[:, 0] = start.x, start.xd
    return x, xd


def _combined_mode(modes, alive):
    """Mode common to every live row, 0 if they differ or none lives."""
    live = modes[alive]
    if live.size == 0 or not np.all(live == live[0]):
        return 0
    return int(live[0])


def track_window(model, q_meas, settings: TrackerSettings, *, x0=None, initial_mode=None, xi_box=None,
                 max_passes: int = WINDOW_MAX_PASSES, rel_tol: float = WINDOW_REL_TOL,
                 max_geometries: int = WINDOW_MAX_GEOMETRIES, backend: str | Backend = Backend.COMPILED,
                 parallel: bool = True, goal: Verdict | None = None,
                 one_motion: int = ONE_MOTION_SAMPLES, explainer: Explainer | None = None,
                 start: WindowStart | None = None, final_search=None, fk_tol: float = WINDOW_FK_TOL,
                 clock=None) -> WindowResult:
    """Verdict of a whole recording by forward-backward window passes (:mod:`verifier.window`).

    Parameters
    ----------
    model : verifier.model.IntervalModel
    q_meas : array_like, shape (K, n)
        Encoder readings, rad, every ``settings.t_s`` seconds.
    settings : TrackerSettings
        The tracker's assumptions and settings (``xi_splits`` gives the geometry sub-boxes).
    x0 : (lo, hi), optional
        Initial pose box ``(n,)``, m.
    initial_mode : {+1, -1}, optional
        Known mode at the first sample (the initial box is then its interval
        forward kinematics).  Give exactly one of ``x0`` and ``initial_mode``.
    xi_box : (lo, hi), optional
        Calibration box ``(m,)``, the robot's by default.
    max_passes : int
        Pass budget per hypothesis after the first forward pass.
    rel_tol : float
        End a round of passes once a pass shrinks the tubes by less than this fraction.
    max_geometries : int
        Budget of geometry sub-boxes per hypothesis: after a round that
        neither refutes nor confirms, the surviving sub-boxes are halved
        while their number stays within it (``settings.xi_splits``' count
        or less: no halving).
    backend : {"compiled", "numpy"}
    parallel : bool
        Compiled backend: geometry sub-boxes in parallel.
    goal : Verdict, optional
        The one verdict the caller asks about (``MODE_CHANGED``: a crossing to
        certify; ``MODE_UNCHANGED``: a bounce).  Only the hypothesis whose
        refutation gives it runs window passes; the other is left consistent
        and incomplete, so any other answer comes out ``unknown`` (or from the
        forward pass).  When the recording is what the caller expects, the
        verdict is the one ``None`` gives, at a fraction of the cost: the true
        hypothesis is never refuted, and its rounds are the costly ones.
        ``None``: both hypotheses.
    one_motion : int
        Samples of the one-motion step (:mod:`verifier.one_motion`): once the budget of sub-boxes is
        spent, after each round, a row is dropped when no single geometry of its sub-box and single
        motion within ``a_max`` in its tubes explain the readings over this many samples around its
        widest pose box (proved by a Farkas certificate), and the others' sub-boxes are narrowed to
        proved bounds of the geometries that can; a step that dropped or narrowed (by
        :data:`~verifier.window.hypotheses.ONE_MOTION_SHRINK`) earns another round without halving, up to
        :data:`~verifier.window.hypotheses.ONE_MOTION_ROUNDS`.  0: not tried.
    explainer : Explainer, optional
        Asked about each hypothesis (of ``goal``'s, when given) once it has
        spent its budget of sub-boxes, before its one-motion step; an
        explained hypothesis runs no more rounds, and when every hypothesis
        asked about is explained the window stops: ``unknown``, reason
        :attr:`VerdictReason.UNDECIDABLE`.  ``None``: never asked (the
        passes, verdict and tubes do not depend on it otherwise).
    start : WindowStart, optional
        The rows and their boxes at the first sample (a tracker's state there),
        instead of ``x0`` or ``initial_mode`` and ``xi_box``: a window that
        starts while the robot moves.
    final_search : (lo, hi), optional
        A box ``(n,)`` known to hold the last pose (the tracker's box there), m: the final boxes of the
        hypotheses are enumerated inside it rather than in the robot's ``x_bounds``.
    fk_tol : float
        Resolution (m) of that enumeration: coarser is faster, with wider final boxes.
    clock : verifier.clock.SampleClock, optional
        When the samples were taken, for an uneven recording (dropped samples, jittered stamps): the
        passes and the pair contraction use its step enclosures.  The one-motion step and the explainer
        assume samples every ``t_s`` and are not run on an uneven clock (a refutation not tried only
        leaves a verdict open).  Every ``settings.t_s`` when None.

    Returns
    -------
    WindowResult
    """
    t0 = time.perf_counter()
    req = _checked_request(model, q_meas, settings, x0=x0, initial_mode=initial_mode, xi_box=xi_box,
                           max_passes=max_passes, rel_tol=rel_tol, max_geometries=max_geometries, backend=backend,
                           parallel=parallel, goal=goal, one_motion=one_motion, explainer=explainer, start=start,
                           final_search=final_search, fk_tol=fk_tol, clock=clock)
    return _run_window(req, t0)


@dataclass(frozen=True, eq=False)
class _Request:
    """The checked arguments of one :func:`track_window` call (see its parameters).

    Attributes
    ----------
    s : TrackerSettings
        The settings validated for the model.
    q : ndarray, shape (K, n)
        The readings, rad, contiguous float64.
    one_motion : int
        Samples of the one-motion step, checked.
    final_search : (lo, hi) or None
        The search box of the last pose, float64 arrays ``(n,)``, m.
    goal : Verdict or None
        The goal as a :class:`Verdict`.
    clock : verifier.clock.SampleClock or None
        An uneven clock of the ``K`` samples; None for steps of ``t_s`` (an even clock is dropped).

    The other attributes are :func:`track_window`'s arguments as given.
    """

    model: object
    q: np.ndarray = field(repr=False)
    s: TrackerSettings
    x0: object
    initial_mode: object
    xi_box: object
    max_passes: int
    rel_tol: float
    max_geometries: int
    backend: object
    parallel: bool
    goal: Verdict | None
    one_motion: int
    explainer: object
    start: WindowStart | None
    final_search: object
    fk_tol: float
    clock: object = None


def _checked_request(model, q_meas, settings, *, x0, initial_mode, xi_box, max_passes, rel_tol, max_geometries,
                     backend, parallel, goal, one_motion, explainer, start, final_search, fk_tol, clock=None) -> _Request:
    """Check :func:`track_window`'s arguments (raising :class:`InputError`) and convert them: a :class:`_Request`."""
    s = settings.validated(model.n)
    q = np.ascontiguousarray(np.asarray(q_meas, dtype=np.float64))
    n = model.n
    if q.ndim != 2 or q.shape[1] != n or q.shape[0] < 1:
        raise InputError(f"q_meas must have shape (K, {n}) with K >= 1, got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise InputError("q_meas must be finite")
    if isinstance(max_passes, bool) or int(max_passes) != max_passes or max_passes < 0:
        raise InputError(f"max_passes must be a non-negative integer, got {max_passes!r}")
    if explainer is not None and not callable(explainer):
        raise InputError(f"explainer must be callable (an Explainer) or None, got {type(explainer).__name__}")
    if isinstance(max_geometries, bool) or int(max_geometries) != max_geometries or max_geometries < 1:
        raise InputError(f"max_geometries must be a positive integer, got {max_geometries!r}")
    if not (0.0 <= rel_tol < 1.0):
        raise InputError(f"rel_tol must be in [0, 1), got {rel_tol!r}")
    one_motion = V.count("one_motion", one_motion)
    if not (fk_tol > 0 and np.isfinite(fk_tol)):
        raise InputError(f"fk_tol must be a positive length, got {fk_tol!r}")
    if final_search is not None:
        final_search = tuple(np.asarray(v, dtype=np.float64).reshape(n) for v in final_search)
        if not np.all(final_search[0] <= final_search[1]):
            raise InputError("final_search must be a box with lo <= hi")
    goal = _goal(goal)
    if sum(v is not None for v in (x0, initial_mode, start)) != 1:
        raise InputError("give exactly one of x0, initial_mode and start")
    if clock is not None:
        if len(clock) != q.shape[0] or clock.t_s != float(s.t_s):
            raise InputError(f"the clock has {len(clock)} times at a period of {clock.t_s!r} s for {q.shape[0]} "
                             f"readings at t_s = {float(s.t_s)!r} s")
        if clock.even:
            clock = None  # steps of t_s: the constant-period window, bit for bit
        else:
            one_motion, explainer = 0, None  # both read samples every t_s (docstring)
    return _Request(model, q, s, x0, initial_mode, xi_box, max_passes, rel_tol, max_geometries, backend, parallel,
                    goal, one_motion, explainer, start, final_search, fk_tol, clock)


def _start_rows(req: _Request, XI):
    """The rows of the first forward pass: ``(xi_rows, x0, flat, first_prior)``.

    ``xi_rows`` are the geometry sub-boxes ``(P, m)`` (the start's, or ``settings.xi_splits``' partition of the
    calibration box ``XI``), ``x0`` the initial pose boxes ``(P, n)``, m, ``flat`` the settings of one row per
    sub-box, and ``first_prior`` the start's prior tubes (``None`` without a start).
    """
    model, q, s, start = req.model, req.q, req.s, req.start
    n, K = model.n, q.shape[0]
    x0 = req.x0
    flat = replace(s, xi_splits=None)
    first_prior = None
    if start is not None:
        if req.xi_box is not None:
            raise InputError("a window start carries its geometry sub-boxes: give start or xi_box, not both")
        if start.rows == 0 or start.x.shape[1:] != (2, n) or start.xi_lo.shape != (start.rows, model.m):
            raise InputError(f"a window start needs at least one row of {model.m} parameters and (2, {n}) boxes")
        xi_rows = (np.ascontiguousarray(start.xi_lo), np.ascontiguousarray(start.xi_hi))
        x0 = (start.x[:, 0].copy(), start.x[:, 1].copy())
        # the start's velocity box holds the initial velocity: the first pass takes it as a prior, and later
        # forward passes from their tubes (which hold it), not from the settings' xd0
        flat = replace(flat, xd0=None)
        first_prior = _start_prior(start, K)
    else:
        sub_lo, sub_hi = partition_xi((XI[0][None, :], XI[1][None, :]), s.xi_splits)
        xi_rows = (np.ascontiguousarray(sub_lo[0]), np.ascontiguousarray(sub_hi[0]))
    P = xi_rows[0].shape[0]
    if x0 is None:
        x0 = initial_box_from_mode(model, q[0], req.initial_mode, s, xi_box=XI, backend=str(Backend(req.backend)))
    x0 = tuple(np.broadcast_to(np.asarray(v, dtype=np.float64), (P, n)).copy() for v in x0)
    return xi_rows, x0, flat, first_prior


def _pass_configs(req: _Request, flat):
    """The step configurations of the passes: ``(first forward, window forward, backward)``."""
    model, backend, parallel = req.model, req.backend, req.parallel
    cfg_f = configure(model, flat, backend, parallel=parallel)
    # the window's passes carry each row's calibration sub-box from sample to sample (keep_xi), and the
    # rows keep it from pass to pass: the true geometry satisfies every sample's loop closure
    cfg_wf = configure(model, replace(flat, keep_xi=True), backend, parallel=parallel)
    cfg_b = configure(model, replace(flat, xd0=None, keep_xi=True), backend, parallel=parallel)  # final velocity: from the tubes
    return cfg_f, cfg_wf, cfg_b


@dataclass(frozen=True, eq=False)
class _Forward:
    """The first forward pass (the tracker's) over the window.

    Attributes
    ----------
    x, xd : ndarray, shape (R, K, 2, n)
        Pose (m) and velocity (m/s) tubes of the rows.
    xi_rows : (lo, hi)
        The rows' geometry sub-boxes ``(R, m)`` after the pass.
    alive : ndarray of bool, shape (R,)
        The rows the pass did not refute.
    m0, mf : int
        Mode common to the live rows at the first and last samples (0: none), ``m0`` the start's when known.
    verdict : Verdict
        The forward pass' verdict.
    """

    x: np.ndarray = field(repr=False)
    xd: np.ndarray = field(repr=False)
    xi_rows: tuple = field(repr=False)
    alive: np.ndarray = field(repr=False)
    m0: int
    mf: int
    verdict: Verdict


def _forward_pass(req: _Request, cfg_f, x0, xi_rows, first_prior) -> _Forward:
    """Run the first forward pass from the boxes ``x0`` of the rows ``xi_rows`` and read its modes and verdict."""
    start, K = req.start, req.q.shape[0]
    fx, fxd, fmode, fbad, fxi = run_pass(cfg_f, req.q, x0, xi_rows, first_prior, req.clock)
    # the rows' sub-boxes after the tracker (contracted only when the settings keep them, keep_xi)
    xi_rows = (np.maximum(xi_rows[0], fxi[0]), np.minimum(xi_rows[1], fxi[1]))
    f_alive = fbad < 0
    if start is not None and start.mode:
        # a row whose boxes certify the other mode than the one known at the start holds no true geometry
        f_alive &= (fmode[:, 0] == 0) | (fmode[:, 0] == start.mode)
    m0 = _combined_mode(fmode[:, 0], f_alive)
    if start is not None and start.mode and f_alive.any():
        m0 = start.mode
    mf = _combined_mode(fmode[:, K - 1], f_alive)
    return _Forward(fx, fxd, xi_rows, f_alive, m0, mf, verdict_of(m0, mf, not f_alive.any()))


def _run_window(req: _Request, t0: float) -> WindowResult:
    """The window of a checked request: the first forward pass, then the hypotheses' passes when it leaves the
    final mode open; ``t0`` is the call's start (:func:`time.perf_counter`, s)."""
    XI = req.model.xi_box() if req.xi_box is None else tuple(np.asarray(v, dtype=np.float64) for v in req.xi_box)
    xi_rows, x0, flat, first_prior = _start_rows(req, XI)
    cfg_f, cfg_wf, cfg_b = _pass_configs(req, flat)
    fwd = _forward_pass(req, cfg_f, x0, xi_rows, first_prior)
    f_alive, xi_rows = fwd.alive, fwd.xi_rows
    if fwd.verdict is Verdict.INCONSISTENT or fwd.m0 == 0:
        results = ()
        verdict = fwd.verdict
        reason = VerdictReason.INCONSISTENT if verdict is Verdict.INCONSISTENT else VerdictReason.NO_INITIAL_MODE
        tubes = [(fwd.x[f_alive], fwd.xd[f_alive])]
    elif fwd.mf != 0:
        # the forward pass decided: the other final mode is refuted by its certified boxes
        mf = fwd.mf
        results = (HypothesisResult(mf, HypothesisStatus.CONSISTENT, Refutation.NONE, 0, int(f_alive.sum()), False,
                                    *tube_hull(fwd.x[f_alive], fwd.xd[f_alive]), xi_rows[0][f_alive],
                                    xi_rows[1][f_alive]),
                   HypothesisResult(-mf, HypothesisStatus.REFUTED, Refutation.FORWARD, 0, 0))
        verdict, reason = fwd.verdict, VerdictReason.CERTIFIED
        tubes = [(fwd.x[f_alive], fwd.xd[f_alive])]
    else:
        results, verdict, reason, tubes = _hypotheses_verdict(req, XI, x0, fwd, cfg_wf, cfg_b)
    return _window_result(req, fwd, results, verdict, reason, tubes, t0)


def _asker(req: _Request, XI, x0, m0):
    """The question :func:`decide` asks the explainer about a hypothesis, ``None`` without an explainer."""
    explainer = req.explainer
    if explainer is None:
        return None
    model, q, s = req.model, req.q, req.s
    x0_given = None if req.initial_mode is not None else (x0[0].min(0), x0[1].max(0))

    def ask(h):
        return explainer(ExplainRequest(model, q, s, XI, x0_given, m0, h.m, h.xlo.copy(), h.xhi.copy(),
                                        *(a.copy() for a in tube_hull(h.tx, h.txd)[:2])))
    return ask


def _hypotheses_verdict(req: _Request, XI, x0, fwd: _Forward, cfg_wf, cfg_b):
    """Decide the final mode left open by the forward pass with the two hypotheses' window passes:
    ``(results, verdict, reason, tubes)``."""
    q, K, m0 = req.q, req.q.shape[0], fwd.m0
    finals = FinalBoxes(req.model, q[K - 1], req.s, str(Backend(req.backend)), req.final_search, req.fk_tol)
    keep = np.nonzero(fwd.alive)[0]
    hyps = [Hypothesis(finals, fwd.xi_rows[0][keep], fwd.xi_rows[1][keep], fwd.x[keep], fwd.xd[keep], m0, m)
            for m in (m0, -m0)]
    if not any(h.refuted for h in hyps):
        full_w = XI[1] - XI[0]  # halving measures widths against the calibration box
        ask = _asker(req, XI, x0, m0)
        decide(hyps, Passes(q, cfg_wf, cfg_b, req.clock), req.max_passes, req.rel_tol, req.max_geometries, full_w,
               _targets(hyps, m0, req.goal), int(req.one_motion), ask)
    else:  # refuted by the last reading alone: the other ran no pass
        for h in hyps:
            h.complete = h.refuted
    results = tuple(h.result() for h in hyps)
    tubes = [(h.tx, h.txd) for h in hyps if not h.refuted]
    alive = [h.final_mode for h in results if h.status is not HypothesisStatus.REFUTED]
    if not alive:
        verdict, reason = Verdict.INCONSISTENT, VerdictReason.INCONSISTENT
    elif len(alive) == 2:
        verdict = Verdict.UNKNOWN
        asked = _targets(hyps, m0, req.goal)
        # the early stop: every hypothesis asked about explained (a wrong claim only costs a verdict)
        undecidable = all(h.explained for h in asked)
        reason = VerdictReason.UNDECIDABLE if undecidable else VerdictReason.BUDGET
    else:
        verdict = Verdict.MODE_UNCHANGED if alive[0] == m0 else Verdict.MODE_CHANGED
        reason = VerdictReason.CERTIFIED
    return results, verdict, reason, tubes


def _window_result(req: _Request, fwd: _Forward, results, verdict, reason, tubes, t0: float) -> WindowResult:
    """The :class:`WindowResult`: the hull of the non-empty ``tubes`` (NaN without any) and their widest
    pose (m) and velocity (m/s) intervals; ``t0`` is the call's start (s)."""
    K, n = req.q.shape[0], req.model.n
    tubes = [t for t in tubes if len(t[0])]
    if tubes:
        x_lo, x_hi, xd_lo, xd_hi = tube_hull(np.concatenate([t[0] for t in tubes]), np.concatenate([t[1] for t in tubes]))
    else:
        x_lo, x_hi, xd_lo, xd_hi = (np.full((K, n), np.nan) for _ in range(4))
    with np.errstate(invalid="ignore"):
        wx = float(np.nanmax(x_hi - x_lo)) if tubes else 0.0
        wv = float(np.nanmax(xd_hi - xd_lo)) if tubes else 0.0
    return WindowResult(verdict=verdict, initial_mode=fwd.m0, forward_verdict=fwd.verdict, hypotheses=results,
                        x_lo=x_lo, x_hi=x_hi, xd_lo=xd_lo, xd_hi=xd_hi, max_width_pose=wx, max_width_velocity=wv,
                        steps=K, elapsed_s=time.perf_counter() - t0, reason=reason)
