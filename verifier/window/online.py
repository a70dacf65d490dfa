"""The online window: :class:`OnlineMonitor`, the assembly mode while the robot moves."""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass, replace

import numpy as np

from crosscert.robots.errors import InputError

from ..settings import TrackerSettings, Verdict
from ..step import Backend, Event, pose_solution_arrays, reading_box
from ..tracker import Tracker
from .offline import WindowStart, track_window
from .passes import hull_of_mode
from .results import HypothesisStatus, OnlineEvent, OnlineResult, WindowState

__all__ = ["OnlineMonitor", "ONLINE_HORIZON", "online_boxes"]

#: Longest anchored window (samples from the anchor to the newest reading) of :class:`OnlineMonitor`: past
#: it the window gives up (``unknown``, :attr:`WindowState.GAVE_UP`) until the tracker certifies a mode again.
#: Bounds the readings kept (``n`` floats and a pose box each) and the work of one attempt (which grows
#: with the window's length).
ONLINE_HORIZON = 2000
#: Resolution (m) of the enumeration of the newest reading's poses in an attempt (coarser than the offline
#: window's :data:`~verifier.window.offline.WINDOW_FK_TOL`: near the locus a finer one costs tens of ms).
ONLINE_FK_TOL = 1e-4
#: Thread switch interval (s) an :class:`OnlineMonitor` with a worker sets (Python's default is 5 ms).
SWITCH_INTERVAL = 1e-4
#: Resolution (m) and bisection widths (m) of the enumeration of the decided mode's poses a re-seeded tracker
#: starts from (as :func:`~verifier.tracker.initial_box_from_mode`'s: the box of a first sample).
RESEED_FK_TOL = 1e-5
RESEED_SMALL = (5e-3, 2e-2, 8e-2)
#: Budget of geometry sub-boxes per hypothesis of a full attempt (the offline window's is 64: on the
#: adversarial runs of tests/test_online.py, 16 decided the same runs at half the cost or less).
ONLINE_MAX_GEOMETRIES = 16
#: Window lengths (samples) at which an inline monitor makes a full attempt after its cheap one: a crossing
#: the tracker alone decides a few samples after losing the mode pays cheap attempts only, decisions come
#: within tens of samples of the crossing, and ``check`` runs the window over the whole recording after the
#: monitor when it is still undecided.
INLINE_FULL = (32, 128)
#: Window length (samples from the anchor) of an inline :class:`OnlineMonitor`'s first attempt; the next
#: ones double it, so the work of a window that never decides stays about twice that of its last attempt.
FIRST_ATTEMPT = 8


@dataclass
class _Anchor:
    """The last sample whose mode the tracker certified, its rows there, and the readings from it on."""

    k: int
    mode: int
    start: WindowStart
    q: list
    x: list  # the tracker's pose box (2, n) at each of those samples: it holds the pose there
    attempts: int = 0
    tried: int = 0  # window length of the last attempt
    tried_full: int = 0  # window length of the last full attempt


#: What :meth:`OnlineMonitor._run` returns for a window that refuted both final modes.
_CONTRADICTED = object()


class _Lane:
    """One tracker and what it certified: the mode, since when, the anchor of an open window.

    A re-seeded lane starts at a window's decision (``offset``: the global index of its tracker's sample 0).
    ``horizon``: longest window, samples (0: no window).
    """

    def __init__(self, tracker: Tracker, offset: int, mode: int, last_mode: int, horizon: int):
        self.tracker, self.offset, self.horizon = tracker, offset, horizon
        self.k = offset - 1
        self.mode = mode  # certified at the newest sample
        self.since = offset if mode else -1  # the sample from which it holds
        self.last_mode = last_mode  # the last certified mode: events are about its changes
        self.consistent = True
        self.anchor = None
        self.window = WindowState.IDLE
        st = tracker.state
        # the rows at the newest certified sample: the next anchor (copied in place: no allocation per sample)
        self._snap = (st.x.copy(), st.xd.copy(), st.xi.copy(), st.row_bad.copy())
        self._snap_k = -1
        self._snap_mode = 0
        self._prev_q = None  # the previous reading and pose box: an anchor's first sample
        self._prev_x = st.x_hull[0].copy()  # overwritten in place at every sample
        self._known = 0  # a re-seeded lane: the mode a window decided at its first sample

    def step(self, q):
        """Track the reading ``q``; returns the events it causes."""
        if not self.consistent:  # an assumption was violated: nothing is certified any more
            self.k += 1
            return []
        r = self.tracker.update(q)
        k = self.k = self.offset + r.k
        events = []
        if self.anchor is not None:
            self.anchor.q.append(q)
            self.anchor.x.append(self.tracker.state.x_hull[0].copy())
        if not r.consistent:
            if self.consistent:
                events.append(OnlineEvent(Event.INCONSISTENT, k, k, 0))
            self.consistent, self.mode, self.since = False, 0, -1
            self.anchor, self.window = None, WindowState.IDLE
        elif r.mode != 0 or self._known:
            mode = r.mode or self._known  # a window's decision holds at the sample it was made for
            if self.anchor is not None or self.window is WindowState.GAVE_UP:
                self.anchor, self.window = None, WindowState.IDLE  # decided by the tracker alone
            if mode != self.mode:
                events.append(self.certified(k, k, mode, False))
            st = self.tracker.state
            for buf, v in zip(self._snap, (st.x, st.xd, st.xi, st.row_bad)):
                np.copyto(buf, v)
            self._snap_k, self._snap_mode = k, mode
        else:
            if self.mode != 0:
                events.append(OnlineEvent(Event.MODE_LOST, k, k, 0))
                self.mode, self.since = 0, -1
                if self.horizon and self._snap_k == k - 1 and self._prev_q is not None:
                    self._open(q)
            if self.anchor is not None and len(self.anchor.q) > self.horizon:
                self.anchor, self.window = None, WindowState.GAVE_UP
        self._prev_q = q
        np.copyto(self._prev_x, self.tracker.state.x_hull[0])
        self._known = 0
        return events

    def boxes(self):
        """Copies of the pose and velocity boxes ``((lo, hi), (lo, hi))`` at the newest sample."""
        st = self.tracker.state
        x, xd = st.x_hull[0], st.xd_hull[0]
        return (x[0].copy(), x[1].copy()), (xd[0].copy(), xd[1].copy())

    def certified(self, k, known_at, mode, by_window):
        """The event of ``mode`` certified from sample ``k`` on."""
        event = Event.MODE_GAINED if self.last_mode in (0, mode) else Event.MODE_CHANGED
        self.mode, self.since, self.last_mode = mode, k, mode
        return OnlineEvent(event, k, known_at, mode, by_window)

    def _open(self, q):
        x, xd, xi, bad = self._snap
        live = bad < 0
        start = WindowStart(np.ascontiguousarray(xi[live, 0]), np.ascontiguousarray(xi[live, 1]), x[live].copy(),
                            xd[live].copy(), self._snap_mode)
        self.anchor = _Anchor(self._snap_k, self.last_mode, start, [self._prev_q, q],
                              [self._prev_x.copy(), self.tracker.state.x_hull[0].copy()])
        self.window = WindowState.OPEN


@dataclass(frozen=True)
class _Attempt:
    """What one window attempt needs, taken under the lock: the lane, its anchor and the readings so far."""

    lane: _Lane
    anchor: _Anchor
    q: np.ndarray
    last_box: np.ndarray  # (2, n): the tracker's pose box at the last reading
    full: bool


class OnlineMonitor:
    """The assembly mode while the robot moves: the tracker, and an anchored window when it loses the mode.

    Every reading goes through the forward :class:`~verifier.tracker.Tracker`
    (:meth:`update`).  While the tracker certifies the mode, its rows are kept
    as the *anchor*.  When it loses the mode, a window opens at the anchor: the
    readings from it to the newest one, reasoned over under both final-mode
    hypotheses (:func:`~verifier.window.track_window` started from the
    tracker's rows at the anchor, :class:`~verifier.window.WindowStart`),
    again as readings arrive.  When one hypothesis is refuted, the mode at the
    newest sample that attempt read is known; the tracker then starts again
    from that mode's boxes there (the surviving hypothesis' pose and velocity
    tubes at that sample, which its passes intersected with the
    forward-kinematics solutions of that mode, and the hull of its surviving
    geometry sub-boxes) and runs over the readings that arrived meanwhile.
    Its boxes are tight again, and the next crossing is tracked like the
    first.

    An attempt is *cheap* (the tracker's geometry sub-boxes, not halved, and
    no one-motion step: tens of ms) or *full* (up to
    :data:`ONLINE_MAX_GEOMETRIES` sub-boxes and the one-motion step: up to
    seconds).  With ``worker=True`` the window runs on a thread of its own
    (the kernels release the GIL) and :meth:`update` never waits for an
    attempt: cheap attempts follow one another over all the readings there
    are, with a full one each time the window has doubled since the last.
    With ``worker=False`` the attempts run inside :meth:`update`, at window
    lengths :data:`FIRST_ATTEMPT`, twice that, ... (cheap; full too at
    :data:`INLINE_FULL`): the answers do not depend on the
    machine's speed (``crosscert check``).  :meth:`settle` runs a full
    attempt over every reading.  Either way every answer holds under the
    tracker's assumptions; only when it comes may differ.

    Memory and work are bounded: a window that reaches ``horizon`` samples
    undecided gives up (:attr:`WindowState.GAVE_UP`, mode not certified)
    until the tracker certifies a mode by itself.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    settings : TrackerSettings
    x0 : (lo, hi)
        Initial pose box ``(n,)``, m.
    xi_box : (lo, hi), optional
        Calibration box ``(m,)``, the robot's by default.
    backend : {"compiled", "numpy"}
    horizon : int
        Longest window, samples (>= 2).
    worker : bool
        The window on a thread (online) or inside :meth:`update` (reproducible).
    window : bool
        False: the tracker alone (no window opens).
    switch_interval : float or None
        With a worker: lower the interpreter's thread switch interval (``sys.setswitchinterval``, process
        wide, s) to this, so that :meth:`update` waits at most about this long for the GIL while the
        window's Python code holds it; ``None`` leaves it.
    spread_hypotheses : bool
        See :class:`~verifier.tracker.Tracker`.

    Examples
    --------
    >>> with OnlineMonitor(model, settings, x0) as mon:    # doctest: +SKIP
    ...     for q in readings:                              # q: (n,) rad
    ...         r = mon.update(q)
    ...         for e in r.events:
    ...             print(e.k, e.event, e.mode)
    ...     mon.settle()                                    # the window's last attempt on every reading
    """

    def __init__(self, model, settings: TrackerSettings, x0, *, xi_box=None,
                 backend: str | Backend = Backend.COMPILED, horizon: int = ONLINE_HORIZON, worker: bool = True,
                 window: bool = True, spread_hypotheses: bool = False,
                 switch_interval: float | None = SWITCH_INTERVAL):
        if isinstance(horizon, bool) or int(horizon) != horizon or horizon < 2:
            raise InputError(f"horizon must be at least 2 samples, got {horizon!r}")
        self.model, self.backend = model, str(Backend(backend))
        self.settings = settings.validated(model.n)
        self.horizon, self._spread = int(horizon), bool(spread_hypotheses)
        tracker = Tracker(model, settings, x0, xi_box=xi_box, backend=backend, spread_hypotheses=spread_hypotheses)
        self._lane = _Lane(tracker, 0, 0, 0, self.horizon if window else 0)
        self.initial_mode = 0
        self.decisions = 0  # windows that decided
        self.inconsistent_at = -1  # the sample at which every geometry hypothesis became empty (-1: none)
        self.max_width_pose = 0.0  # largest side of the pose (m) and velocity (m/s) boxes while consistent
        self.max_width_velocity = 0.0
        self._queued = []  # events of a decision the worker applied, for the next update to report
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._idle = threading.Condition(self._lock)
        self._busy = False
        self._settling = False
        self._error = None  # an exception of the worker, raised by the next update or settle
        self._closed = False
        self._thread = None
        if worker and window:
            if switch_interval is not None and sys.getswitchinterval() > switch_interval:
                # the window's Python code holds the GIL between kernels: update waits at most this long for it
                sys.setswitchinterval(switch_interval)
            self._thread = threading.Thread(target=self._work, name="crosscert-window", daemon=True)
            self._thread.start()

    # ------------------------------------------------------------------ the update path
    def update(self, q) -> OnlineResult:
        """Feed the reading ``q`` ``(n,)``, rad: the tracker's step, and what the window found meanwhile."""
        q = np.array(q, dtype=np.float64).reshape(-1)
        if q.shape != (self.model.n,) or not np.isfinite(q).all():
            raise InputError(f"a reading must be {self.model.n} finite joint values, got {q!r}")
        with self._lock:
            self._raise_worker_error()
            if self._closed:
                raise InputError("this OnlineMonitor is closed")
            lane = self._lane
            events, self._queued = self._queued, []
            events += lane.step(q)
            if lane.k == 0 and lane.mode:
                self.initial_mode = lane.mode
            if lane.anchor is not None:
                if self._thread is None:
                    events += self._inline(lane)
                else:
                    self._wake.notify()
            lane = self._lane
            x, xd = lane.boxes()
            self._note(events)
            if lane.consistent:  # on Python floats: the same differences as numpy's, without its calls' cost
                self.max_width_pose = max(self.max_width_pose, *map(float.__sub__, x[1].tolist(), x[0].tolist()))
                self.max_width_velocity = max(self.max_width_velocity,
                                              *map(float.__sub__, xd[1].tolist(), xd[0].tolist()))
            return OnlineResult(lane.k, lane.mode, x, xd, lane.consistent, tuple(events), lane.window)

    @property
    def k(self) -> int:
        """Index of the newest sample read (-1 before the first)."""
        return self._lane.k

    @property
    def mode(self) -> int:
        """Mode certified at the newest sample (0: not certified)."""
        return self._lane.mode

    @property
    def since(self) -> int:
        """The sample from which the mode at the newest sample is certified (-1: not certified)."""
        return self._lane.since

    @property
    def consistent(self) -> bool:
        return self._lane.consistent

    @property
    def window(self) -> WindowState:
        return self._lane.window

    @property
    def boxes(self) -> tuple:
        """``(x, xd)``: the pose (m) and velocity (m/s) boxes ``(lo, hi)`` at the newest sample, from the
        decided mode's boxes once a window decided (also after :meth:`settle`)."""
        with self._lock:
            return self._lane.boxes()

    @property
    def tracker(self) -> Tracker:
        """The tracker of the newest sample (a new one after each window decision)."""
        return self._lane.tracker

    def verdict(self) -> Verdict:
        """The verdict on the readings so far: the certified modes at the first and newest sample compared."""
        lane = self._lane
        if not lane.consistent:
            return Verdict.INCONSISTENT
        if self.initial_mode == 0 or lane.mode == 0:
            return Verdict.UNKNOWN
        return Verdict.MODE_UNCHANGED if lane.mode == self.initial_mode else Verdict.MODE_CHANGED

    def settle(self, timeout: float | None = None) -> list:
        """Let the window finish with the readings read so far: a full attempt over all of them, unless one
        decided first.  Returns the events that caused (not reported again by :meth:`update`).

        ``timeout`` (s) bounds the wait for the worker; ``None`` waits as long as it takes.
        """
        with self._lock:
            if self._thread is None:
                lane = self._lane
                events = []
                if lane.anchor is not None and lane.anchor.tried_full < len(lane.anchor.q):
                    events = self._decide(lane, self._attempt(lane, full=True))
                self._note(events)
                return events
            self._settling = True
            self._wake.notify()
            try:
                self._idle.wait_for(lambda: self._closed or (not self._busy and not self._pending_work(self._lane)),
                                    timeout)
            finally:
                self._settling = False
            self._raise_worker_error()
            events, self._queued = self._queued, []
            self._note(events)
            return events

    def _note(self, events) -> None:
        for e in events:
            if e.event is Event.INCONSISTENT and self.inconsistent_at < 0:
                self.inconsistent_at = e.k

    def _raise_worker_error(self):
        if self._error is not None:
            raise self._error

    def close(self, timeout: float | None = None) -> None:
        """Stop the worker; further updates are refused.  An attempt running ends first: ``timeout`` (s)
        bounds the wait for it (the thread is a daemon: an interrupted program need not wait)."""
        with self._lock:
            self._closed = True
            self._wake.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ the window
    def _attempt(self, lane: _Lane, full: bool) -> _Attempt:
        a = lane.anchor
        a.attempts += 1
        a.tried = len(a.q)
        if full:
            a.tried_full = a.tried
        return _Attempt(lane, a, np.array(a.q), a.x[len(a.q) - 1].copy(), full)

    def _run(self, at: _Attempt):
        """One window over the attempt's readings (no lock held): the surviving hypothesis of a decided
        window, :data:`_CONTRADICTED` when the window refuted both (an assumption was violated), or None."""
        rows = at.anchor.start.rows
        opts = ({"max_geometries": max(rows, ONLINE_MAX_GEOMETRIES)} if at.full
                else {"max_geometries": rows, "one_motion": 0})
        w = track_window(self.model, at.q, self.settings, start=at.anchor.start, backend=self.backend,
                         parallel=False, final_search=(at.last_box[0], at.last_box[1]), fk_tol=ONLINE_FK_TOL, **opts)
        if w.verdict is Verdict.INCONSISTENT:
            return _CONTRADICTED
        if w.verdict not in (Verdict.MODE_CHANGED, Verdict.MODE_UNCHANGED):
            return None
        return next(h for h in w.hypotheses if h.status is not HypothesisStatus.REFUTED)

    def _apply(self, lane: _Lane, at: _Attempt, h, backlog) -> tuple:
        """The lane after an attempt's answer ``h`` (not None), with its first event and the events of
        ``backlog`` (the readings from the attempt's last one on) through it."""
        if h is _CONTRADICTED:
            # the readings from the anchor on fit no motion under the assumptions: nothing more is certified
            j = at.anchor.k + len(at.q) - 1
            new = _Lane(lane.tracker, lane.offset, 0, lane.last_mode, 0)
            new.consistent = False  # its tracker is the lane's, never stepped again
            return new, OnlineEvent(Event.INCONSISTENT, j, -1, 0, True), []
        new, first = self._reseeded(at, h)
        return new, first, self._catch_up(new, backlog)

    def _reseeded(self, at: _Attempt, h):
        """A lane whose tracker starts at the attempt's last sample from hypothesis ``h``'s boxes there."""
        j = at.anchor.k + len(at.q) - 1
        xi = (h.xi_lo.min(axis=0), h.xi_hi.max(axis=0))
        x0 = self._decided_box(at.q[-1], h.final_mode, xi, (h.x_lo[-1], h.x_hi[-1]))
        # its velocity box comes from the window (set below), not from the settings' bound at rest
        tracker = Tracker(self.model, replace(self.settings, xd0=None), x0, xi_box=xi, backend=self.backend,
                          spread_hypotheses=self._spread)
        tracker.state.xd[:, 0], tracker.state.xd[:, 1] = h.xd_lo[-1], h.xd_hi[-1]
        lane = _Lane(tracker, j, 0, at.anchor.mode, self.horizon)
        # the decided mode holds at j before the new tracker reads q_j (it may then fail to certify it: lost)
        first = lane.certified(j, -1, h.final_mode, True)
        lane._known = h.final_mode
        return lane, first

    def _decided_box(self, q, mode, xi, tube):
        """The pose box of ``mode`` for the reading ``q`` and geometries ``xi`` inside the window's ``tube``
        box there: the hull of that mode's forward-kinematics solutions (undecided ones included) within the
        tube, enumerated finer than the attempt did; the tube itself when the enumeration gives up."""
        search = (np.asarray(tube[0], dtype=np.float64), np.asarray(tube[1], dtype=np.float64))
        Q = reading_box(q, self.settings.eps_q)
        for small in RESEED_SMALL:
            sols = pose_solution_arrays(self.model, Q, xi, search, tol=RESEED_FK_TOL, small=small,
                                        backend=self.backend)
            if sols is not None:
                break
        box = hull_of_mode(sols, mode, search)
        if box is None:  # no pose of that mode in the tube: the tracker will find the assumptions violated
            return search[0].copy(), search[1].copy()
        return np.maximum(box[0], search[0]), np.minimum(box[1], search[1])

    def _inline(self, lane: _Lane) -> list:
        """``worker=False``: the attempts due at this window length (lock held)."""
        a = lane.anchor
        L = len(a.q)
        if L < FIRST_ATTEMPT or L & (L - 1):  # lengths 8, 16, 32, ...
            return []
        events = self._decide(lane, self._attempt(lane, full=False))
        if self._lane is lane and lane.anchor is a and L in INLINE_FULL:
            events += self._decide(lane, self._attempt(lane, full=True))
        return events

    def _decide(self, lane: _Lane, at: _Attempt) -> list:
        """Run an attempt inline and apply its answer (lock held)."""
        h = self._run(at)
        if h is None:
            return []
        new, first, events = self._apply(lane, at, h, at.anchor.q[len(at.q) - 1:])
        return self._swap(new, first, events, known_at=lane.k)

    @staticmethod
    def _catch_up(new: _Lane, readings) -> list:
        events = []
        for q in readings:
            events += new.step(q)
        return events

    def _swap(self, new: _Lane, first: OnlineEvent, events: list, known_at: int) -> list:
        """Make ``new`` the lane (lock held); the window's event first, known at sample ``known_at``."""
        if not new.consistent:
            new.k = self._lane.k
        self._lane = new
        self.decisions += 1
        return [replace(first, known_at=known_at), *events]

    def _pending_work(self, lane: _Lane) -> bool:
        """An attempt is due: readings no attempt read, or a full attempt over them all when settling."""
        a = lane.anchor
        if a is None:
            return False
        return a.tried < len(a.q) or (self._settling and a.tried_full < len(a.q))

    def _work(self):
        """The worker thread: attempts over the open window (see the class) until closed."""
        while True:
            with self._lock:
                self._busy = False
                self._idle.notify_all()
                self._wake.wait_for(lambda: self._closed or self._pending_work(self._lane))
                if self._closed:
                    return
                lane = self._lane
                a = lane.anchor
                L = len(a.q)
                # cheap ones back to back; a full one once the window doubled since the last, or when settling
                full = (L >= FIRST_ATTEMPT and L >= 2 * a.tried_full) or (self._settling and L == a.tried)
                at = self._attempt(lane, full=full)
                self._busy = True
            try:
                h = self._run(at)
            except Exception as exc:  # noqa: BLE001 - kept for the update path to raise, not lost in the thread
                with self._lock:
                    self._error = exc
                    self._closed = True
                    self._idle.notify_all()
                return
            if h is None:
                continue

            def valid():
                return self._lane is lane and lane.anchor is at.anchor
            # the readings from the attempt's last one on, through the new tracker: outside the lock as far as
            # they go, the few that came meanwhile under it, then the swap
            with self._lock:
                if not valid():
                    continue  # the tracker decided by itself (or gave up) meanwhile: the answer is moot
                done = len(at.q) - 1
                readings = list(at.anchor.q[done:])
            new, first, events = self._apply(lane, at, h, readings)
            with self._lock:
                if not valid():
                    continue
                events += self._catch_up(new, at.anchor.q[done + len(readings):])
                self._queued += self._swap(new, first, events, known_at=lane.k)


def online_boxes(model, q, settings: TrackerSettings, x0, *, xi_box=None, backend: str | Backend = Backend.COMPILED,
                 horizon: int = ONLINE_HORIZON) -> dict:
    """The boxes an inline :class:`OnlineMonitor` reports at every sample of the readings ``q`` ``(K, n)``
    (rad): ``x_lo, x_hi, xd_lo, xd_hi`` ``(K, n)`` (m, m/s), ``mode`` ``(K,)`` (from a window's decision on,
    the decided mode's boxes), and ``decided`` (the samples its windows decided), for a figure."""
    rows, decided = [], []
    with OnlineMonitor(model, settings, x0, xi_box=xi_box, backend=backend, horizon=horizon, worker=False) as mon:
        for qk in np.asarray(q, dtype=np.float64):
            r = mon.update(qk)
            rows.append((r.x[0], r.x[1], r.xd[0], r.xd[1], r.mode))
            decided += [e.k for e in r.events if e.by_window and e.mode]
    out = {key: np.array([row[i] for row in rows]) for i, key in enumerate(("x_lo", "x_hi", "xd_lo", "xd_hi", "mode"))}
    out["decided"] = decided
    return out
