"""The online window: :class:`OnlineMonitor`, the assembly mode while the robot moves."""

from __future__ import annotations

import math
import pickle
import sys
import threading
from dataclasses import replace

import numpy as np

from crosscert.robots.errors import InputError

from ..clock import SampleClock
from ..settings import TrackerSettings, Verdict
from ..step import Backend, Event
from ..tracker import Tracker
from .lane import (FIRST_ATTEMPT, ONLINE_FK_TOL, ONLINE_MAX_GEOMETRIES, RESEED_FK_TOL,  # noqa: F401 (its names)
                   RESEED_SMALL, Attempt, Lane, Reasoner, catch_up, contradicted, due, next_attempt,
                   stamps_from)
from .results import OnlineEvent, OnlineResult, WindowState
from .worker import WindowProcess, WindowWorkerStopped, pack_readings

__all__ = ["OnlineMonitor", "ONLINE_HORIZON", "online_boxes"]

#: Longest anchored window (samples from the anchor to the newest reading) of :class:`OnlineMonitor`: past
#: it the window gives up (``unknown``, :attr:`WindowState.GAVE_UP`) until the tracker certifies a mode again.
#: Bounds the readings kept (``n`` floats and a pose box each) and the work of one attempt (which grows
#: with the window's length).
ONLINE_HORIZON = 2000
#: Thread switch interval (s) an :class:`OnlineMonitor` with a worker thread sets (Python's default is 5 ms).
SWITCH_INTERVAL = 1e-4
#: Window lengths (samples) at which an inline monitor makes a full attempt after its cheap one: a crossing
#: the tracker alone decides a few samples after losing the mode pays cheap attempts only, decisions come
#: within tens of samples of the crossing, and ``check`` runs the window over the whole recording after the
#: monitor when it is still undecided.
INLINE_FULL = (32, 128)
#: Readings sent to the worker process at once: a frame costs the update path a few µs and wakes the
#: worker; an attempt sees the readings at most this many samples late.
FEED_EVERY = 4
#: Longest wait (s) of the constructor for the worker process to start.
START_WAIT_S = 60.0
#: Where the window's attempts run (``worker``): a process of its own, a thread, or inside ``update``.
WORKERS = ("process", "thread", "inline")


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
    seconds).  With a worker (``worker=True``: a process of its own,
    :mod:`verifier.window.worker`; ``"thread"``: a thread, whose Python code
    shares the interpreter lock with :meth:`update`) :meth:`update` never
    waits for an attempt: cheap attempts follow one another over all the
    readings there are, with a full one each time the window has doubled
    since the last (:func:`~verifier.window.lane.next_attempt`).
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
    worker : {True, "process", "thread", False}
        The window in a worker process (True, the default: the constructor waits 1-2 s for it to start;
        a thread when the robot cannot cross to another process), on a thread, or inside :meth:`update`
        (False: reproducible).
    window : bool
        False: the tracker alone (no window opens).
    switch_interval : float or None
        With a worker thread: lower the interpreter's thread switch interval (``sys.setswitchinterval``, process
        wide, s) to this, so that :meth:`update` waits at most about this long for the GIL while the
        window's Python code holds it; ``None`` leaves it.
    spread_hypotheses : bool
        See :class:`~verifier.tracker.Tracker`.
    clock : verifier.clock.SampleClock, optional
        An empty clock of ``settings.t_s`` when every reading comes with its stamp (:meth:`update`'s ``t``):
        dropped samples, or stamps within its ``stamp_error`` (:mod:`verifier.clock`).  Readings every
        ``t_s`` when None.

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
                 backend: str | Backend = Backend.COMPILED, horizon: int = ONLINE_HORIZON, worker: bool | str = True,
                 window: bool = True, spread_hypotheses: bool = False,
                 switch_interval: float | None = SWITCH_INTERVAL, clock=None):
        if isinstance(horizon, bool) or int(horizon) != horizon or horizon < 2:
            raise InputError(f"horizon must be at least 2 samples, got {horizon!r}")
        self.model, self.backend = model, str(Backend(backend))
        self.settings = settings.validated(model.n)
        self.horizon, self._spread = int(horizon), bool(spread_hypotheses)
        kind = {True: "process", False: "inline"}.get(worker, worker) if window else "inline"
        if kind not in WORKERS:
            raise InputError(f"worker must be one of {WORKERS} (True: process, False: inline), got {worker!r}")
        self._reasoner = Reasoner(model, self.settings, self.backend, self.horizon, self._spread,
                                  None if clock is None else clock.stamp_error)
        tracker = Tracker(model, settings, x0, xi_box=xi_box, backend=backend, spread_hypotheses=spread_hypotheses,
                          clock=clock)
        self._lane = Lane(tracker, 0, 0, 0, self.horizon if window else 0)
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
        self._proc = None
        if kind == "process" and not self._start_process(x0):
            kind = "thread"  # the robot cannot cross to another process (a file the child cannot import, ...)
        if kind == "thread":
            if switch_interval is not None and sys.getswitchinterval() > switch_interval:
                # the window's Python code holds the GIL between kernels: update waits at most this long for it
                sys.setswitchinterval(switch_interval)
            self._thread = threading.Thread(target=self._work, name="crosscert-window", daemon=True)
            self._thread.start()

    # ------------------------------------------------------------------ the update path
    def update(self, q, t: float | None = None) -> OnlineResult:
        """Feed the reading ``q`` ``(n,)``, rad, stamped ``t`` (s; only with a ``clock``): the tracker's step,
        and what the window found meanwhile."""
        q = np.array(q, dtype=np.float64).reshape(-1)  # a copy of its own: kept by the window
        if q.shape != (self.model.n,) or not all(map(math.isfinite, q.tolist())):  # Python floats: cheaper
            raise InputError(f"a reading must be {self.model.n} finite joint values, got {q!r}")
        with self._lock:
            self._raise_worker_error()
            if self._closed:
                raise InputError("this OnlineMonitor is closed")
            if self._proc is not None:
                self._answers()
            lane = self._lane
            events, self._queued = self._queued, []
            events += lane.step(q, t)
            if lane.k == 0 and lane.mode:
                self.initial_mode = lane.mode
            if self._proc is not None:
                self._feed(lane)
            elif lane.anchor is not None:
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
        """The tracker of the newest sample (another one after each window decision)."""
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
            if self._proc is not None:
                return self._settle_process(timeout)
            if self._thread is None:
                lane = self._lane
                events = []
                if lane.anchor is not None and lane.anchor.tried_full < len(lane.anchor.q):
                    events = self._decide(lane, Attempt.of(lane, lane.anchor, full=True))
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
        if self._proc is not None:
            self._proc.close(timeout)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ------------------------------------------------------------------ the window
    def _run(self, at: Attempt):
        """One window over the attempt's readings (no lock held): see :meth:`Reasoner.run`."""
        return self._reasoner.run(at)

    def _inline(self, lane: Lane) -> list:
        """``worker=False``: the attempts due at this window length (lock held)."""
        a = lane.anchor
        L = len(a.q)
        if L < FIRST_ATTEMPT or L & (L - 1):  # lengths 8, 16, 32, ...
            return []
        events = self._decide(lane, Attempt.of(lane, lane.anchor, full=False))
        if self._lane is lane and lane.anchor is a and L in INLINE_FULL:
            events += self._decide(lane, Attempt.of(lane, lane.anchor, full=True))
        return events

    def _decide(self, lane: Lane, at: Attempt) -> list:
        """Run an attempt inline and apply its answer (lock held)."""
        h = self._run(at)
        if h is None:
            return []
        new, first, events = self._reasoner.apply(lane, at, h, at.anchor.q[len(at.q) - 1:],
                                                  stamps_from(at.anchor, len(at.q) - 1))
        return self._swap(new, first, events, known_at=lane.k)

    def _swap(self, new: Lane, first: OnlineEvent, events: list, known_at: int) -> list:
        """Make ``new`` the lane (lock held); the window's event first, known at sample ``known_at``."""
        if not new.consistent:
            new.k = self._lane.k
        self._lane = new
        self.decisions += 1
        return [replace(first, known_at=known_at), *events]

    def _pending_work(self, lane: Lane) -> bool:
        """An attempt is due (:func:`~verifier.window.lane.due`)."""
        return due(lane.anchor, self._settling)

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
                at = Attempt.of(lane, a, *next_attempt(a, self._settling))
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
                stamps = stamps_from(at.anchor, done, done + len(readings))
            new, first, events = self._reasoner.apply(lane, at, h, readings, stamps)
            with self._lock:
                if not valid():
                    continue
                events += catch_up(new, at.anchor.q[done + len(readings):], stamps_from(at.anchor, done + len(readings)))
                self._queued += self._swap(new, first, events, known_at=lane.k)


    # ------------------------------------------------------------------ the window in a worker process
    def _start_process(self, x0) -> bool:
        """Start the child (:mod:`verifier.window.worker`) and build, ahead of any decision, the trackers a
        decided lane's state is copied into: building one and its first step cost about 2 ms, which the
        update path would otherwise pay at the decision.  False (no child) when the child could not set up
        its model: the robot does not pickle, or does not load in a fresh interpreter."""
        x0 = tuple(np.array(v, dtype=np.float64) for v in x0)
        try:
            proc = WindowProcess(self.model.robot, self.settings, self.backend, self.horizon, self._spread, x0,
                                 self._reasoner.stamp_error)
        except (pickle.PicklingError, TypeError, AttributeError):
            return False
        self._proc = proc
        self._sent = None  # the anchor the child holds (the lane's, once sent)
        self._sent_n = 0  # its readings sent
        self._id = 0  # that anchor's number: answers about another one are moot
        self._token = 0  # of the last settle request
        self._spares = []
        for _ in range(2):  # one for the decided lane, one for the next decision
            t = Tracker(self.model, self._reasoner.reseed_settings(), x0, backend=self.backend,
                        spread_hypotheses=self._spread)
            t.update(np.zeros(self.model.n))  # its compiled entry point found now (the state is overwritten)
            self._spares.append(t)
        self._own = list(self._spares)
        # the child's start (an interpreter, the model, the kernels from the cache: 1-2 s) before the
        # first reading, so that a window opening early is worked on at once; past the bound, frames wait
        self._proc.started.wait(START_WAIT_S)
        if not self._proc.ready:
            self._proc.close(0.0)
            self._proc = None
            return False
        return True

    def _feed(self, lane: Lane, flush: bool = False) -> None:
        """Send the child what it lacks of the lane's window: the anchor when it opened, else the new
        readings (every :data:`FEED_EVERY` samples, or now: ``flush``), or that it closed (lock held)."""
        a = lane.anchor
        if a is None:
            if self._sent is not None:
                self._proc.send(("drop",))
                self._sent = None
            return
        if a is not self._sent:
            self._id += 1
            self._sent, self._sent_n = a, len(a.q)
            self._proc.send(("open", self._id, a.k, a.mode, a.start, a.q, a.x, a.t))
            return
        if len(a.q) - self._sent_n >= (1 if flush else FEED_EVERY):
            self._proc.send(("q", self._id, pack_readings(a.q[self._sent_n:], a.x[self._sent_n:],
                                                          stamps_from(a, self._sent_n))))
            self._sent_n = len(a.q)

    def _answers(self) -> None:
        """Apply what the child answered since the last call (lock held): a decided lane takes the place of
        the tracker's after the readings the child had not seen; a moot answer is dropped."""
        inbox = self._proc.inbox
        if not inbox.frames and inbox.ended is None:  # the update path's usual case: nothing to do
            return
        for frame in inbox.take(block=False):
            kind = frame[0]
            if kind == "error":
                self._error, self._closed = frame[1], True
            elif kind == "settled":
                continue
            elif frame[1] == self._id and self._sent is not None and self._lane.anchor is self._sent:
                lane, used = self._lane, frame[2]
                if kind == "contradicted":
                    new, first, events = contradicted(lane, lane.anchor.k + used - 1)
                else:
                    new = Lane.restore(frame[3], self._spares.pop())
                    first, events = frame[4], frame[5] + catch_up(new, lane.anchor.q[used:],
                                                                  stamps_from(lane.anchor, used))
                    if any(lane.tracker is t for t in self._own):
                        self._spares.append(lane.tracker)
                self._sent = None  # the child dropped it; a window of the new lane is sent as a new one
                self._queued += self._swap(new, first, events, known_at=lane.k)
        if inbox.ended is not None and self._error is None and not self._closed:
            self._error, self._closed = WindowWorkerStopped(inbox.ended), True
        self._raise_worker_error()

    def _settle_process(self, timeout) -> list:
        """:meth:`settle` with the child (lock held): until a settle request finds no attempt due; a lane a
        decision re-seeded may open a window of its own, which is settled in turn."""
        while True:
            self._answers()
            self._feed(self._lane, flush=True)
            if self._sent is None:
                break
            self._token += 1
            self._proc.send(("settle", self._token))
            inbox, before = self._proc.inbox, self._lane
            with inbox.cond:
                done = inbox.cond.wait_for(lambda: inbox.ended is not None or any(
                    f[0] == "error" or f == ("settled", self._token) for f in inbox.frames), timeout)
            self._answers()
            if not done or self._lane is before:
                break
        events, self._queued = self._queued, []
        self._note(events)
        return events


def online_boxes(model, q, settings: TrackerSettings, x0, *, xi_box=None, backend: str | Backend = Backend.COMPILED,
                 horizon: int = ONLINE_HORIZON, clock=None) -> dict:
    """The boxes an inline :class:`OnlineMonitor` reports at every sample of the readings ``q`` ``(K, n)``
    (rad): ``x_lo, x_hi, xd_lo, xd_hi`` ``(K, n)`` (m, m/s), ``mode`` ``(K,)`` (from a window's decision on,
    the decided mode's boxes), and ``decided`` (the samples its windows decided), for a figure; ``clock``: the
    readings' uneven times (a :class:`~verifier.clock.SampleClock` of ``K`` samples), None for steps of ``t_s``."""
    rows, decided = [], []
    stamps = None if clock is None else clock.stamps()
    fresh = None if clock is None else SampleClock(clock.t_s, clock.stamp_error)
    with OnlineMonitor(model, settings, x0, xi_box=xi_box, backend=backend, horizon=horizon, worker=False,
                       clock=fresh) as mon:
        for k, qk in enumerate(np.asarray(q, dtype=np.float64)):
            r = mon.update(qk, None if stamps is None else stamps[k])
            rows.append((r.x[0], r.x[1], r.xd[0], r.xd[1], r.mode))
            decided += [e.k for e in r.events if e.by_window and e.mode]
    out = {key: np.array([row[i] for row in rows]) for i, key in enumerate(("x_lo", "x_hi", "xd_lo", "xd_hi", "mode"))}
    out["decided"] = decided
    return out
