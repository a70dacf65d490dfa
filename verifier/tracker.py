"""Sound pose-and-velocity tracking through Type 2 singularities (Algorithm 1).

At every sample ``k`` the tracker holds boxes ``[x]_k`` and ``[xd]_k`` that
contain the true end-effector pose and velocity, for a batch of ``B``
scenarios at once:

1. **prediction** over the sampling interval ``t_s``, from ``|xdd| <= a_max``
   (Taylor with Lagrange remainder, one component at a time)::

       [xd]_{k+1} = [xd]_k + t_s [a]
       [x]_{k+1}  = [x]_k  + t_s [xd]_k + (t_s^2 / 2) [a]

   (Algorithm 1 line 7 as printed adds ``t_s [xd]_k`` with the velocity
   contracted *at* ``t_k`` only, which does not enclose the velocity over the
   interval; the Taylor form does.)
2. **measurement**: ``[q]_{k+1} = q_meas + [-eps_q, eps_q]``; velocity
   information from the joint samples by one of three models
   (:class:`VelocityModel`): the default, sound *displacement* model relates
   ``x_k - x_{k-j}`` to ``q_k - q_{k-j}`` over several baselines ``j`` (its
   truncation error ``(h/2) a_max`` stays in Cartesian space); the
   *joint-fd* model uses the finite difference ``(q_{k+1} - q_k) / t_s`` with
   quantisation ``2 eps_q / t_s`` plus truncation ``(t_s / 2) qdd`` from a
   given or derived joint-acceleration bound (:func:`_qdd_over_step`); the
   *paper* model keeps only the quantisation term (unsound).
3. **contraction** to a fixpoint: HC4Revise and interval Newton on
   ``f(x, q, xi) = 0`` for the pose, Gauss–Seidel on ``J_x xd = -J_q qd`` for
   the velocity; optionally the calibration box ``[xi]`` is kept contracted
   from step to step (the true geometry is constant).
4. **mode**: +1 / -1 when ``mode_sign * det J_x`` has that sign over the whole
   box, else 0.

The calibration box may be partitioned into geometry hypotheses
(``xi_splits``), tracked side by side; a hypothesis whose box becomes empty
is refuted, the reported boxes are the hull of the surviving ones, and a mode
is certified only when every survivor certifies it.  If every hypothesis
becomes empty, some assumption (``a_max``, ``[xi]``, ``eps_q``, the initial
box, the joint-acceleration bound) was violated: the scenario is reported
``inconsistent`` at that step and never given a verdict.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field

import numpy as np

from . import interval as I
from crosscert.robots.errors import InputError
from .settings import TrackerSettings, Verdict, VelocityModel
from .state import ROW_FIELDS, SCENARIO_FIELDS
from .step import (Backend, Event, StepResult, advance, checked_sample, configure, init_state, kernel_array,
                   pose_solutions)

__all__ = [
    "Verdict",
    "VelocityModel",
    "TrackerSettings",
    "TrackResult",
    "BatchResult",
    "initial_box_from_mode",
    "verdict_of",
    "track",
    "track_batch",
    "SampleStream",
    "Tracker",
]


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Per-scenario summaries of a batched run (arrays of shape ``(B,)``).

    ``initial_mode``/``final_mode``: certified mode at the first/last sample
    (0 = not certified); ``certified_at_step``: first sample from which the
    final mode stays certified to the end (-1 if none); ``inconsistent_at_step``:
    first sample where a box became empty (-1 if none);
    ``max_width_pose``/``max_width_velocity``: largest box side over the run
    (m, m/s) before any inconsistency.
    """

    verdict: np.ndarray
    initial_mode: np.ndarray
    final_mode: np.ndarray
    certified_at_step: np.ndarray
    inconsistent_at_step: np.ndarray
    max_width_pose: np.ndarray
    max_width_velocity: np.ndarray
    steps: int
    elapsed_s: float


@dataclass(frozen=True, eq=False)
class TrackResult:
    """One tracked run with its per-step boxes.

    Attributes
    ----------
    verdict : Verdict
    initial_mode, final_mode : int
        Certified modes at the first and last sample (0 = not certified).
    certified_at_step, inconsistent_at_step : int
        See :class:`BatchResult` (-1 = none).
    max_width_pose, max_width_velocity : float
        ``m_x`` (m) and ``m_xd`` (m/s) of the paper's Table II.
    x_lo, x_hi, xd_lo, xd_hi : array (K, n)
        Pose (m) and velocity (m/s) boxes at every sample.
    mode : array (K,)
        Certified mode at every sample.
    qdd_bound : array (K, n)
        Joint-acceleration bound used at every sample, rad/s^2 (``inf`` where none).
    steps : int
    elapsed_s : float
    """

    verdict: Verdict
    initial_mode: int
    final_mode: int
    certified_at_step: int
    inconsistent_at_step: int
    max_width_pose: float
    max_width_velocity: float
    x_lo: np.ndarray
    x_hi: np.ndarray
    xd_lo: np.ndarray
    xd_hi: np.ndarray
    mode: np.ndarray
    qdd_bound: np.ndarray
    steps: int
    elapsed_s: float
    settings: TrackerSettings = field(repr=False, default=None)

    def summary(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "verdict": self.verdict.value,
            "initial_mode": int(self.initial_mode),
            "final_mode": int(self.final_mode),
            "certified_at_step": None if self.certified_at_step < 0 else int(self.certified_at_step),
            "inconsistent_at_step": None if self.inconsistent_at_step < 0 else int(self.inconsistent_at_step),
            "steps": int(self.steps),
            "max_width_pose_m": float(self.max_width_pose),
            "max_width_velocity_mps": float(self.max_width_velocity),
            "elapsed_s": float(self.elapsed_s),
        }


#: Widths (pose units) below which a solution box with a certified mode is kept, tried in turn.
_INITIAL_SMALL = (5e-3, 2e-2, 8e-2)


def initial_box_from_mode(model, q0, mode: int, settings: TrackerSettings, xi_box=None, x_search=None,
                          backend: str = "compiled"):
    """Enclosure of the pose in assembly mode ``mode`` for the first sample.

    Encloses every solution of ``f(x, q, xi) = 0`` with ``q in q0 + [eps_q]``,
    ``xi in [xi]``, inside ``x_search`` (the robot's ``x_bounds``), and returns
    the hull of the solution boxes of the requested mode.  ``backend``
    (``"compiled"`` or ``"numpy"``) runs the branch and prune.

    Raises
    ------
    InputError
        If no solution of that mode exists (the mode does not match the data),
        or a solution box's mode cannot be certified (start too close to a
        Type 2 singularity).
    """
    s = settings.validated(model.n)
    q0 = np.asarray(q0, dtype=np.float64)
    Q = I.sub(q0, q0, s.eps_q, s.eps_q)[0], I.add(q0, q0, s.eps_q, s.eps_q)[1]
    XI = model.xi_box() if xi_box is None else xi_box
    if x_search is None:
        lo, hi = model.robot.x_bounds
        x_search = (np.asarray(lo, dtype=float), np.asarray(hi, dtype=float))
    # A solution set wider than `small` (many uncertain parameters, angles in
    # the pose) is bisected down to `tol` and exhausts the budget: retry coarser.
    for small in _INITIAL_SMALL:
        sols = pose_solutions(model, Q, XI, x_search, tol=1e-5, small=small, backend=backend)
        if sols is not None:
            break
    if sols is None:
        raise InputError("could not isolate the forward-kinematics solutions of the first sample: it is likely too close "
                         "to the Type 2 locus for the calibration box (docs/your-robot.md); start the recording "
                         "farther from the locus, or give --x0")
    if not sols:
        raise InputError("the first joint sample has no forward-kinematics solution with the calibration box: check the robot and the data")
    if any(m == 0 for _, m in sols):
        raise InputError(
            "the first sample is too close to a Type 2 singularity to certify its assembly mode; give --x0 instead"
        )
    mine = [b for b, m in sols if m == mode]
    if not mine:
        found = sorted({m for _, m in sols})
        raise InputError(
            f"initial mode {mode:+d} does not match the data: the first sample only admits mode(s) {', '.join(f'{m:+d}' for m in found)}"
        )
    lo = np.min([b[0] for b in mine], axis=0)
    hi = np.max([b[1] for b in mine], axis=0)
    return lo, hi


def verdict_of(initial_mode: int, final_mode: int, inconsistent: bool) -> Verdict:
    """The verdict of a run from its certified modes at the first and last sample (0: not certified).

    ``inconsistent`` (a box became empty) overrides everything; a mode not
    certified at either end gives ``unknown``.
    """
    if inconsistent:
        return Verdict.INCONSISTENT
    if initial_mode == 0 or final_mode == 0:
        return Verdict.UNKNOWN
    return Verdict.MODE_UNCHANGED if initial_mode == final_mode else Verdict.MODE_CHANGED


def track_batch(model, q_meas, settings: TrackerSettings, x0, xi_box=None, record: bool = False, progress=None,
                backend: str = "compiled", parallel: bool = True, spread_hypotheses: bool = False, clock=None):
    """Run the tracker on ``B`` scenarios at once.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    q_meas : array (B, K, n) or SampleStream
        Encoder readings, rad, sampled every ``settings.t_s``; a
        :class:`SampleStream` supplies them one sample at a time, so memory
        stays ``O(B)`` however long the run.
    settings : TrackerSettings
    x0 : (lo, hi)
        Initial pose boxes, arrays ``(B, n)`` or ``(n,)``, m.
    xi_box : (lo, hi), optional
        Calibration box ``(m,)`` or ``(B, m)``; the robot's by default.
    record : bool
        Also return every box (memory ``O(B K n)``).
    progress : callable, optional
        Called as ``progress(k)`` after each sample (after each block of
        samples with the compiled backend).
    backend : {"compiled", "numpy"}
        The compiled kernels (default) or the numpy reference
        (:mod:`verifier.step`).
    parallel, spread_hypotheses : bool
        Compiled backend: spread the scenarios over the thread slots, or the
        geometry hypotheses of each sample over numba's threads; the same
        results either way (see
        :class:`verifier.step.StepConfig`).
    clock : verifier.clock.SampleClock, optional
        When the samples were taken (the same for every scenario): an uneven
        recording's stamps, dropped samples or jitter (:mod:`verifier.clock`);
        every ``settings.t_s`` when None.

    Returns
    -------
    BatchResult, and when ``record`` a dict of arrays ``x_lo, x_hi, xd_lo,
    xd_hi`` ``(B, K, n)``, ``mode`` ``(B, K)``, ``qdd_hi`` ``(B, K, n)``.
    """
    t0 = time.perf_counter()
    config = configure(model, settings, backend, parallel=parallel, spread_hypotheses=spread_hypotheses)
    q_meas = _sample_stream(model, q_meas)
    B, K, n = q_meas.batch, q_meas.steps, model.n
    _check_clock(clock, K, settings)
    state = init_state(config, x0, batch=B, xi_box=xi_box)
    rec = _record_arrays(B, K, n) if record else None
    _run_blocks(config, state, q_meas, n, rec, progress, clock)
    res = _batch_result(state, B, K, t0)
    return (res, rec) if record else res


def _sample_stream(model, q_meas) -> SampleStream:
    """``q_meas`` as a :class:`SampleStream`: a stream as given, an array checked to be ``(B, K, n)``, rad."""
    if not isinstance(q_meas, SampleStream):
        q_meas = np.asarray(q_meas, dtype=np.float64)
        if q_meas.ndim != 3 or q_meas.shape[2] != model.n:
            raise InputError(f"q_meas must have shape (B, K, {model.n}), got {q_meas.shape}")
        q_meas = SampleStream.from_array(q_meas)
    return q_meas


def _record_arrays(B: int, K: int, n: int) -> dict:
    """The arrays :func:`track_batch` records every box in: ``x_lo, x_hi, xd_lo, xd_hi, qdd_hi`` ``(B, K, n)``
    filled with NaN and ``mode`` ``(B, K)`` with 0."""
    rec = {k: np.full((B, K, n), np.nan) for k in ("x_lo", "x_hi", "xd_lo", "xd_hi", "qdd_hi")}
    rec["mode"] = np.zeros((B, K), np.int8)
    return rec


def _check_clock(clock, K: int, settings) -> None:
    """Refuse a clock of another length or period than the readings and settings it comes with."""
    if clock is None:
        return
    if len(clock) != K:
        raise InputError(f"the clock has {len(clock)} sample times for {K} samples")
    if clock.t_s != float(settings.t_s):
        raise InputError(f"the clock's period {clock.t_s!r} s is not the settings' t_s {float(settings.t_s)!r} s")


def _run_blocks(config, state, q_meas: SampleStream, n: int, rec, progress, clock=None) -> None:
    """Advance ``state`` (pose dimension ``n``) over every sample of ``q_meas``, a block of :data:`_BLOCK`
    samples per call with the compiled backend (one sample with numpy), writing the boxes into ``rec`` (unless
    ``None``) and calling ``progress(k)`` for each sample after its block."""
    B, K = q_meas.batch, q_meas.steps
    record = rec is not None
    chunk = _BLOCK if config.backend is Backend.COMPILED else 1
    for k0 in range(0, K, chunk):
        k1 = min(K, k0 + chunk)
        q = np.stack([np.asarray(q_meas.sample(k), dtype=np.float64).reshape(B, -1) for k in range(k0, k1)], axis=1)
        block = None
        if record:
            block = (np.empty((B, k1 - k0, 2, n)), np.empty((B, k1 - k0, 2, n)), np.empty((B, k1 - k0), np.int64),
                     np.empty((B, k1 - k0, n)))
        advance(config, state, q, block, clock=clock)
        if record:
            rec["x_lo"][:, k0:k1], rec["x_hi"][:, k0:k1] = block[0][:, :, 0], block[0][:, :, 1]
            rec["xd_lo"][:, k0:k1], rec["xd_hi"][:, k0:k1] = block[1][:, :, 0], block[1][:, :, 1]
            rec["mode"][:, k0:k1] = block[2]
            rec["qdd_hi"][:, k0:k1] = block[3]
        if progress is not None:
            for k in range(k0, k1):
                progress(k)


def _batch_result(state, B: int, K: int, t0: float) -> BatchResult:
    """The :class:`BatchResult` of the state of ``B`` scenarios after ``K`` samples; ``t0`` is the run's start
    (:func:`time.perf_counter`, s)."""
    bad_at = state.bad_at.copy()
    init_mode = state.init_mode.astype(np.int8)
    final = np.where(bad_at < 0, state.mode, 0).astype(np.int8)
    cert = np.where(final != 0, state.streak, -1)
    verdict = np.empty(B, dtype=object)
    for b in range(B):
        verdict[b] = verdict_of(init_mode[b], final[b], bad_at[b] >= 0)
    return BatchResult(
        verdict=verdict,
        initial_mode=init_mode,
        final_mode=final,
        certified_at_step=cert,
        inconsistent_at_step=bad_at,
        max_width_pose=state.max_width_pose.copy(),
        max_width_velocity=state.max_width_velocity.copy(),
        steps=K,
        elapsed_s=time.perf_counter() - t0,
    )


#: Samples per kernel call of the compiled backend (progress is reported per block).
_BLOCK = 256


@dataclass(frozen=True)
class SampleStream:
    """Joint samples supplied one at a time: ``sample(k)`` returns ``(B, n)``.

    Parameters
    ----------
    batch : int
        Number of scenarios ``B``.
    steps : int
        Number of samples ``K``.
    sample : callable
        ``sample(k) -> array (B, n)`` of encoder readings at ``t = k t_s``, rad.
    """

    batch: int
    steps: int
    sample: object

    @staticmethod
    def from_array(q):
        """Stream over an array of shape ``(B, K, n)``."""
        q = np.asarray(q, dtype=np.float64)
        return SampleStream(q.shape[0], q.shape[1], lambda k: q[:, k, :])


def track(model, q_meas, settings: TrackerSettings, *, x0=None, initial_mode=None, xi_box=None, progress=None,
          backend: str = "compiled", spread_hypotheses: bool = False, clock=None) -> TrackResult:
    """Track one recorded joint trajectory and give a verdict.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    q_meas : array (K, n)
        Encoder readings, rad, every ``settings.t_s`` seconds.
    settings : TrackerSettings
    x0 : (lo, hi), optional
        Initial pose box ``(n,)``, m.
    initial_mode : {+1, -1}, optional
        Known assembly mode at the first sample (then the initial box is the
        interval forward-kinematics enclosure of that mode).  Give exactly one
        of ``x0`` and ``initial_mode``.
    xi_box : (lo, hi), optional
        Calibration box, the robot's by default.
    backend : {"compiled", "numpy"}
    spread_hypotheses, clock
        See :func:`track_batch`.

    Returns
    -------
    TrackResult
    """
    t0 = time.perf_counter()
    q_meas = np.asarray(q_meas, dtype=np.float64)
    if q_meas.ndim != 2 or q_meas.shape[1] != model.n:
        raise InputError(f"q_meas must have shape (K, {model.n}), got {q_meas.shape}")
    if len(q_meas) < 2:
        raise InputError("at least two joint samples are needed")
    if not np.all(np.isfinite(q_meas)):
        raise InputError("joint samples must be finite (found NaN or inf)")
    if (x0 is None) == (initial_mode is None):
        raise InputError("give exactly one of an initial pose box (x0) and an initial assembly mode")
    if initial_mode is not None:
        if initial_mode not in (1, -1):
            raise InputError(f"initial mode must be +1 or -1, got {initial_mode}")
        x0 = initial_box_from_mode(model, q_meas[0], initial_mode, settings, xi_box, backend=backend)
    else:
        lo, hi = (np.asarray(v, dtype=np.float64) for v in x0)
        if lo.shape != (model.n,) or hi.shape != (model.n,) or np.any(~(lo <= hi)):
            raise InputError(f"initial pose box must be {model.n} intervals with lo <= hi, got {x0}")
        x0 = (lo, hi)
    res, rec = track_batch(model, q_meas[None], settings, x0, xi_box=xi_box, record=True, progress=progress,
                           backend=backend, spread_hypotheses=spread_hypotheses, clock=clock)
    verdict = res.verdict[0]
    if initial_mode is not None and verdict is not Verdict.INCONSISTENT and res.initial_mode[0] != initial_mode:
        # the given mode's box did not certify at step 0 after contraction
        verdict = Verdict.UNKNOWN if res.initial_mode[0] == 0 else verdict
    return TrackResult(
        verdict=verdict,
        initial_mode=int(res.initial_mode[0]),
        final_mode=int(res.final_mode[0]),
        certified_at_step=int(res.certified_at_step[0]),
        inconsistent_at_step=int(res.inconsistent_at_step[0]),
        max_width_pose=float(res.max_width_pose[0]),
        max_width_velocity=float(res.max_width_velocity[0]),
        x_lo=rec["x_lo"][0],
        x_hi=rec["x_hi"][0],
        xd_lo=rec["xd_lo"][0],
        xd_hi=rec["xd_hi"][0],
        mode=rec["mode"][0],
        qdd_bound=rec["qdd_hi"][0],
        steps=res.steps,
        elapsed_s=time.perf_counter() - t0,
        settings=settings,
    )


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
    clock : verifier.clock.SampleClock, optional
        An empty clock of the settings' ``t_s`` when the readings come with
        stamps (:meth:`update`'s ``t``): dropped samples, or jitter within its
        ``stamp_error``.  Every ``t_s`` when None.

    Examples
    --------
    >>> tr = Tracker(model, settings, x0)          # doctest: +SKIP
    >>> r = tr.update(q)                            # q: (n,) rad
    >>> r.mode, r.x, r.events                       # doctest: +SKIP
    """

    def __init__(self, model, settings, x0, *, xi_box=None, backend: str | Backend = Backend.COMPILED,
                 spread_hypotheses: bool = False, clock=None):
        self.config = configure(model, settings, backend, spread_hypotheses=spread_hypotheses)
        self.state = init_state(self.config, x0, batch=1, xi_box=xi_box)
        _check_clock(clock, 0, settings)
        self.clock = clock
        self._mode = 0
        self._consistent = True

    def update(self, q, t: float | None = None) -> StepResult:
        """Advance by one reading ``q`` ``(n,)``, rad, stamped ``t`` (s; only with a :attr:`clock`); returns
        the new boxes and events."""
        st = self.state
        if self.clock is None and t is not None:
            raise InputError("a stamp t needs a tracker made with a clock (Tracker(..., clock=SampleClock(t_s)))")
        # the reading checked before its stamp is taken: a refused reading changes nothing
        self._advance(checked_sample(self.config, st, np.asarray(q, dtype=np.float64).reshape(1, -1)), t)
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

    def _advance(self, q, t) -> None:
        """One checked reading ``q`` ``(1, 1, n)`` through the kernels; with a clock, stamped ``t`` (s) and with
        the constants of its step (kept to the last ``depth`` samples' times)."""
        if self.clock is None:
            self.config.impl.advance(self.config, self.state, q)
            return
        if t is None:
            raise InputError("this tracker has a clock: give each reading's stamp t (s)")
        self.clock.append(t)
        self.clock.forget_before(self.state.k - self.config.depth)
        c = self.clock.constants(self.config.const, self.config.settings, self.state.k)
        # a step of one period: the constant period's constants, the same call as without a clock
        self.config.impl.advance(self.config, self.state, q, None, None, None if c is self.config.const else c)

    def step_reading(self, q, t: float | None = None) -> tuple:
        """:meth:`update` for a caller that checked the reading (:class:`~verifier.window.OnlineMonitor`):
        ``q`` an ``(n,)`` array of finite values, rad (copied unless a writable, C-contiguous float64 one).  Returns ``(k, mode,
        consistent)``; the boxes are in :attr:`state`.  No second check and no copies: on the update path
        every call into numpy costs again after the process slept between samples (caches cold)."""
        st = self.state
        if q.dtype != np.float64 or not (q.flags.c_contiguous and q.flags.writeable):  # the kernel's one signature
            q = kernel_array(q)
        self._advance(q.reshape(1, 1, -1), t)
        mode, consistent = int(st.mode[0]), bool(st.bad_at[0] < 0)
        self._mode, self._consistent = mode, consistent
        return st.k - 1, mode, consistent

    def snapshot(self) -> dict:
        """Copies of the state's arrays and counters, as plain (picklable) data: what :meth:`restore`
        reads, in another process too."""
        st = self.state
        return {"arrays": {f: getattr(st, f).copy() for f in ROW_FIELDS + SCENARIO_FIELDS}, "k": st.k,
                "mode": self._mode, "consistent": self._consistent, "clock": copy.deepcopy(self.clock)}

    def restore(self, snap: dict) -> None:
        """Continue from ``snap``, a :meth:`snapshot` of a tracker of the same settings (up to ``xd0``, read
        only by the first box) and shapes: copied into this tracker's arrays in place, so that the compiled
        step's arguments, built once per state, stay valid."""
        st = self.state
        for f, v in snap["arrays"].items():
            np.copyto(getattr(st, f), v)
        st.k, self._mode, self._consistent = snap["k"], snap["mode"], snap["consistent"]
        self.clock = copy.deepcopy(snap.get("clock"))  # the stamps the snapshot's tracker read (None: none)
