"""The online window's parts: a tracker's lane, its anchor, an attempt, and the reasoning that decides one.

:class:`~verifier.window.OnlineMonitor` runs these inline, on a thread, or (the reasoning) in a worker
process (:mod:`verifier.window.worker`); a lane travels between processes as plain data (:meth:`Lane.export`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..clock import SampleClock
from ..settings import TrackerSettings, Verdict
from ..step import Event, pose_solution_arrays, reading_box
from ..tracker import Tracker
from .offline import WindowStart, track_window
from .passes import hull_of_mode
from .results import HypothesisStatus, OnlineEvent, WindowState

__all__ = ["Anchor", "Attempt", "Lane", "Reasoner", "CONTRADICTED", "ONLINE_FK_TOL", "ONLINE_MAX_GEOMETRIES",
           "RESEED_FK_TOL", "RESEED_SMALL", "FIRST_ATTEMPT",
           "catch_up", "contradicted", "due", "next_attempt", "stamps_from"]

#: Resolution (m) of the enumeration of the newest reading's poses in an attempt (coarser than the offline
#: window's :data:`~verifier.window.offline.WINDOW_FK_TOL`: near the locus a finer one costs tens of ms).
ONLINE_FK_TOL = 1e-4
#: Resolution (m) and bisection widths (m) of the enumeration of the decided mode's poses a re-seeded tracker
#: starts from (as :func:`~verifier.tracker.initial_box_from_mode`'s: the box of a first sample).
RESEED_FK_TOL = 1e-5
RESEED_SMALL = (5e-3, 2e-2, 8e-2)
#: Budget of geometry sub-boxes per hypothesis of a full attempt (the offline window's is 64: on the
#: adversarial runs of tests/test_online.py, 16 decided the same runs at half the cost or less).
ONLINE_MAX_GEOMETRIES = 16
#: Window length (samples from the anchor) of an inline :class:`OnlineMonitor`'s first attempt; the next
#: ones double it, so the work of a window that never decides stays about twice that of its last attempt.
#: A worker's first full attempt comes at that length too.
FIRST_ATTEMPT = 8


@dataclass
class Anchor:
    """The last sample whose mode the tracker certified, its rows there, and the readings from it on."""

    k: int
    mode: int
    start: WindowStart
    q: list
    x: list  # the tracker's pose box (2, n) at each of those samples: it holds the pose there
    t: list | None = None  # their stamps, s, when the readings come with stamps (a tracker with a clock)
    attempts: int = 0
    tried: int = 0  # window length of the last attempt
    tried_full: int = 0  # window length of the last full attempt
    ladder: int = 0  # the last inline length tried when settling (next_attempt)


#: What :meth:`Reasoner.run` returns for a window that refuted both final modes.
CONTRADICTED = "contradicted"


class Lane:
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
        self._prev_q = None  # the previous reading, its stamp and pose box: an anchor's first sample
        self._prev_t = None
        self._prev_x = st.x_hull[0].copy()  # overwritten in place at every sample
        self._known = 0  # a re-seeded lane: the mode a window decided at its first sample

    def export(self) -> dict:
        """The lane as plain (picklable) data: its fields and its tracker's :meth:`~Tracker.snapshot`."""
        fields = {key: v for key, v in vars(self).items() if key != "tracker"}
        return {"fields": fields, "tracker": self.tracker.snapshot()}

    @classmethod
    def restore(cls, data: dict, tracker: Tracker) -> "Lane":
        """The lane :meth:`export` gave, on ``tracker`` (same settings and shapes), which takes its state."""
        tracker.restore(data["tracker"])
        lane = cls.__new__(cls)
        vars(lane).update(data["fields"], tracker=tracker)
        return lane

    def step(self, q, t=None):
        """Track the reading ``q`` stamped ``t`` (s; None without a clock; checked: see
        :meth:`Tracker.step_reading`); returns the events it causes."""
        if not self.consistent:  # an assumption was violated: nothing is certified any more
            self.k += 1
            return []
        rk, r_mode, r_consistent = self.tracker.step_reading(q, t)
        k = self.k = self.offset + rk
        events = []
        if self.anchor is not None:
            self.anchor.q.append(q)
            self.anchor.x.append(self.tracker.state.x_hull[0].copy())
            if self.anchor.t is not None:
                self.anchor.t.append(t)
        if not r_consistent:
            if self.consistent:
                events.append(OnlineEvent(Event.INCONSISTENT, k, k, 0))
            self.consistent, self.mode, self.since = False, 0, -1
            self.anchor, self.window = None, WindowState.IDLE
        elif r_mode != 0 or self._known:
            mode = r_mode or self._known  # a window's decision holds at the sample it was made for
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
                    self._open(q, t)
            if self.anchor is not None and len(self.anchor.q) > self.horizon:
                self.anchor, self.window = None, WindowState.GAVE_UP
        self._prev_q, self._prev_t = q, t
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

    def _open(self, q, t):
        x, xd, xi, bad = self._snap
        live = bad < 0
        start = WindowStart(np.ascontiguousarray(xi[live, 0]), np.ascontiguousarray(xi[live, 1]), x[live].copy(),
                            xd[live].copy(), self._snap_mode)
        self.anchor = Anchor(self._snap_k, self.last_mode, start, [self._prev_q, q],
                             [self._prev_x.copy(), self.tracker.state.x_hull[0].copy()],
                             None if self.tracker.clock is None else [self._prev_t, t])
        self.window = WindowState.OPEN


@dataclass(frozen=True)
class Attempt:
    """What one window attempt needs, taken under the lock: the lane, its anchor and the readings so far."""

    lane: Lane | None  # None in a worker process, which holds the anchor only
    anchor: Anchor
    q: np.ndarray
    last_box: np.ndarray  # (2, n): the tracker's pose box at the last reading
    full: bool
    t: np.ndarray | None = None  # the readings' stamps, s (None: every t_s)

    @classmethod
    def of(cls, lane: Lane | None, anchor: Anchor, full: bool, length: int | None = None) -> "Attempt":
        """An attempt over the first ``length`` readings of ``anchor`` (all so far by default; noted in its
        counts)."""
        n = len(anchor.q) if length is None else length
        anchor.attempts += 1
        if n < len(anchor.q):  # a settling monitor's inline length
            anchor.ladder = n
        else:
            anchor.tried = n
            if full:
                anchor.tried_full = n
        return cls(lane, anchor, np.array(anchor.q[:n]), anchor.x[n - 1].copy(), full,
                   None if anchor.t is None else np.array(anchor.t[:n]))


@dataclass(frozen=True)
class Reasoner:
    """What a window attempt and a re-seeded lane are computed with; the same in every process."""

    model: object
    settings: TrackerSettings
    backend: str
    horizon: int
    spread: bool
    stamp_error: float | None = None  # the readings' stamps' error bound, s (None: readings every t_s)

    def clock(self):
        """An empty clock for a tracker of stamped readings (:mod:`verifier.clock`), None without stamps."""
        return None if self.stamp_error is None else SampleClock(self.settings.t_s, self.stamp_error)

    def run(self, at: Attempt):
        """One window over the attempt's readings: the surviving hypothesis of a decided window,
        :data:`CONTRADICTED` when the window refuted both (an assumption was violated), or None."""
        rows = at.anchor.start.rows
        opts = ({"max_geometries": max(rows, ONLINE_MAX_GEOMETRIES)} if at.full
                else {"max_geometries": rows, "one_motion": 0})
        clock = None if at.t is None else SampleClock.from_stamps(at.t, self.settings.t_s, self.stamp_error)
        w = track_window(self.model, at.q, self.settings, start=at.anchor.start, backend=self.backend,
                         parallel=False, final_search=(at.last_box[0], at.last_box[1]), fk_tol=ONLINE_FK_TOL,
                         clock=clock, **opts)
        if w.verdict is Verdict.INCONSISTENT:
            return CONTRADICTED
        if w.verdict not in (Verdict.MODE_CHANGED, Verdict.MODE_UNCHANGED):
            return None
        return next(h for h in w.hypotheses if h.status is not HypothesisStatus.REFUTED)

    def reseed_settings(self) -> TrackerSettings:
        """A re-seeded tracker's settings: its velocity box comes from the window, not from ``xd0``."""
        return replace(self.settings, xd0=None)

    def reseeded(self, at: Attempt, h):
        """A lane whose tracker starts at the attempt's last sample from hypothesis ``h``'s boxes there, and
        its first event."""
        j = at.anchor.k + len(at.q) - 1
        xi = (h.xi_lo.min(axis=0), h.xi_hi.max(axis=0))
        x0 = self.decided_box(at.q[-1], h.final_mode, xi, (h.x_lo[-1], h.x_hi[-1]))
        tracker = Tracker(self.model, self.reseed_settings(), x0, xi_box=xi, backend=self.backend,
                          spread_hypotheses=self.spread, clock=self.clock())
        tracker.state.xd[:, 0], tracker.state.xd[:, 1] = h.xd_lo[-1], h.xd_hi[-1]
        lane = Lane(tracker, j, 0, at.anchor.mode, self.horizon)
        # the decided mode holds at j before the new tracker reads q_j (it may then fail to certify it: lost)
        first = lane.certified(j, -1, h.final_mode, True)
        lane._known = h.final_mode
        return lane, first

    def decided_box(self, q, mode, xi, tube):
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

    def apply(self, lane: Lane, at: Attempt, h, backlog, stamps=None) -> tuple:
        """The lane after an attempt's answer ``h`` (not None), with its first event and the events of
        ``backlog`` (the readings from the attempt's last one on, stamped ``stamps``) through it."""
        if h is CONTRADICTED:
            return contradicted(lane, at.anchor.k + len(at.q) - 1)
        new, first = self.reseeded(at, h)
        return new, first, catch_up(new, backlog, stamps)


def next_attempt(anchor: Anchor, settling: bool) -> tuple:
    """A worker's next attempt, ``(full, length)``: cheap attempts back to back over every reading, a full
    one once the window doubled since the last full one, or over every reading when settling; then, when
    that one left the window open, cheap ones over the power-of-two lengths of an inline monitor not tried
    yet (a worker fed faster than real time skips them: without these, its last word could miss an answer
    ``check`` finds)."""
    L = len(anchor.q)
    if settling and anchor.tried_full == L and anchor.ladder < L:
        return False, max(FIRST_ATTEMPT, 2 * anchor.ladder)
    return (L >= FIRST_ATTEMPT and L >= 2 * anchor.tried_full) or (settling and L == anchor.tried), L


def due(anchor: Anchor | None, settling: bool) -> bool:
    """An attempt is due: readings no attempt read, or, when settling, a full attempt over them all or a
    cheap one over an inline length not tried (:func:`next_attempt`)."""
    if anchor is None:
        return False
    L = len(anchor.q)
    return anchor.tried < L or (settling and (anchor.tried_full < L or max(FIRST_ATTEMPT, 2 * anchor.ladder) < L))


def contradicted(lane: Lane, j: int) -> tuple:
    """The lane after a window that found the readings up to sample ``j`` fit no motion under the
    assumptions: nothing more is certified.  ``(lane, first event, [])``."""
    new = Lane(lane.tracker, lane.offset, 0, lane.last_mode, 0)
    new.consistent = False  # its tracker is the lane's, never stepped again
    return new, OnlineEvent(Event.INCONSISTENT, j, -1, 0, True), []


def catch_up(new: Lane, readings, stamps=None) -> list:
    """Step ``new`` over ``readings`` (stamped ``stamps``, s, when its tracker has a clock); their events."""
    events = []
    for i, q in enumerate(readings):
        events += new.step(q, None if stamps is None else stamps[i])
    return events


def stamps_from(anchor: Anchor, start: int, stop: int | None = None):
    """The stamps of the anchor's readings ``start .. stop - 1`` (None when its readings carry none)."""
    return None if anchor.t is None else anchor.t[start:stop]
