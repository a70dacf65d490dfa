"""The refutation's orchestration: counterexample searches by speed, run ahead on an executor while the
speed search runs, and the bisection that turns their rows into the refutation bound.

:class:`Refuter` starts the coarse scan's searches (:func:`refute_speed`, module-level so that a worker
process can run it) and :func:`refutation_search` asks the final questions with the final ``v_min`` as
its top (:func:`planner.certify.crossing.certify_crossing` drives both).  The searches themselves are
:mod:`.search`'s; the bounds they use are :func:`refute_overrides`'.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from concurrent.futures import CancelledError, Executor

import numpy as np

from crosscert.robots.errors import InputError, SimulationError

from ..execution import joint_error
from ..models import kinematic_model
from ..plan import plan_crossing
from ..task import ResolvedBounds
from .results import SpeedRefutation
from .search import refutation_bound, verified_counterexample

log = logging.getLogger(__name__)

__all__ = ["Refuter", "refutation_search", "refute_speed", "refute_overrides", "load_model", "timed",
           "REFUTE_CPU_TIME", "REFUTE_CAP_VARIABLES"]


def timed(fn, *args, **kwargs):
    """``(fn(*args, **kwargs), seconds it took)``: module-level, so that an executor can run it elsewhere."""
    t0 = time.perf_counter()
    value = fn(*args, **kwargs)
    return value, time.perf_counter() - t0


#: IPOPT time cap per counterexample attempt, s.  On the benchmark task of
#: docs/planning.md every verified counterexample took <= 0.2 s (<= 60
#: iterations); attempts near the bound can wander for 10-25 s before declaring
#: infeasibility, and a stopped attempt proves nothing either way (it only
#: costs bound tightness).
REFUTE_CPU_TIME = 2.0
#: Size (unknowns) of the largest counterexample NLP that gets :data:`REFUTE_CPU_TIME` as it is; a larger
#: one gets it scaled by its size (:func:`planner.refute.nlp.scaled_cpu_time`).  Every search of the
#: two-joint benchmark task from 0.3 m/s up is below it (3845 unknowns at 0.3 m/s); the three-joint
#: benchmark's plans at 0.05-0.15 m/s have 29580-10380 unknowns, where IPOPT needs 3-6 CPU-s to converge
#: (docs/planning.md, "The 3-RPR's refutation search").
REFUTE_CAP_VARIABLES = 4000


def load_model(robot) -> None:
    """Build (and keep, :mod:`planner.models`) the robot's ``KinematicModel`` in this process for
    :func:`refute_speed` (in the calling thread)."""
    kinematic_model(robot)


def refute_overrides(b: ResolvedBounds) -> dict:
    """The bounds a counterexample search of a certifying run uses (:func:`planner.refute.refutation_bound`'s
    ``bounds``), from the bounds for one plan (:meth:`ResolvedBounds.for_plan`): the readings within
    ``eps_q + tracking_error``, ``a_max`` per axis, and the initial speed bound."""
    a = b.assumptions
    return {"eps_q": joint_error(b.eps_q, b.tracking_error, down=True), "a_max": np.array(a.a_max, float),
            "v0_max": np.array(a.xd0, float)}


def refute_speed(robot, task, b, m0, starts, v, kin=None, warm=None):
    """Counterexample search on the planned readings at speed ``v``, with that plan's own ``a_max`` (``b``:
    the certification's :class:`~planner.task.ResolvedBounds`).

    Module-level so that any executor can run it in another process; builds
    (and keeps) the robot's ``KinematicModel`` there.  A speed the planner cannot plan gives
    a row with no counterexample and the planner's message as status.  ``warm``: a verified
    counterexample at a neighbouring speed, the start of the first attempt (:func:`refutation_bound`).
    """
    if kin is None:
        kin = kinematic_model(robot)
    try:
        plan = plan_crossing(kin, task, v, b)
    except (InputError, SimulationError) as exc:
        nan = float("nan")
        return SpeedRefutation(float(v), 0, False, False, None, nan, nan, nan, f"no plan: {exc}", 0.0, ())
    # a given a_max bounds the search as it is: not held against this plan's peak as a certificate's is
    overrides = refute_overrides(b if b.a_max_given is not None else b.for_plan(plan))
    return refutation_bound(kin, lambda _v: (plan.q, b.t_s), [v], m0=m0, xi_starts=starts,
                                   bounds=overrides, max_cpu_time=REFUTE_CPU_TIME, warm=warm,
                                   cap_variables=REFUTE_CAP_VARIABLES).rows[0]


class Refuter:
    """Counterexample searches by speed: on an executor, or run here when asked.

    The coarse scan's speeds (:meth:`submit`) are searched in the order the
    scan's bisection of :func:`refutation_search` asks them, one at a time on
    the executor while the speed search runs, over the scan speeds up to the
    fastest speed the speed search has failed so far (:meth:`failed_at`:
    ``v_min`` lies above it) and below the slowest it has certified
    (:meth:`drop_from`: a certified speed cannot be refuted, and no search at
    or above it starts).  What runs
    ahead of time is only a guess of what the final search asks: the final
    search, with the final ``v_min`` as its top, asks its own speeds, takes the
    rows of those already searched (each speed's search is the same whenever
    it runs) and searches the others then; so neither the rows it reports nor
    the bound depend on timing.

    Parameters
    ----------
    robot, task, b, m0, starts
        The arguments of :func:`refute_speed` before the speed.
    kin : KinematicModel or None
        This process's model, for searches run here.
    executor : concurrent.futures.Executor or None
        Where searches run in the background (None: here, on demand).
    own_executor : bool
        Shut ``executor`` down in :meth:`close`.
    warm : planner.refute.Counterexample or None
        The start of every search not given one of its own (:func:`refute_speed`'s ``warm``).
    tol : float
        Resolution of the bound, m/s (of the searches ahead; :func:`refutation_search` is given its own).
    """

    def __init__(self, robot, task, b, m0, starts, kin, executor: Executor | None, *, own_executor: bool = False,
                 warm=None, tol: float = 0.01):
        self._args = (robot, task, b, m0, starts)
        self._tol = tol
        self._warm = warm
        self._kin = kin
        self._executor = executor
        self._own = own_executor
        self._closed = False  # after close(): no search starts any more (an interrupted certification ends)
        self._futures: dict = {}  # (speed, start's key) -> Future
        self._scan: set = set()
        self._top = math.inf  # the slowest speed certified so far
        self._below = -math.inf  # the fastest speed the speed search failed so far: v_min lies above it
        self._ahead = False  # a search started ahead of time (or the model's loading) is running
        self._loaded = False  # the model's loading was asked of the executor
        self._rows: dict = {}
        self._lock = threading.Lock()  # drop_from comes from the search, result from the helper thread

    def submit(self, speeds) -> None:
        """Add ``speeds`` (m/s) to the coarse scan; with an executor, start searching the scan's first question.

        The first question is chosen once the executor has built the robot's model (:func:`load_model`), under
        the top the speed search has reached by then: its fastest speeds certify while the worker starts.
        """
        with self._lock:
            self._scan.update(speeds)
            start = self._executor is not None and not self._loaded and not self._closed
            if start:
                self._ahead = self._loaded = True
                future = self._executor.submit(load_model, self._args[0])
        if start:
            future.add_done_callback(self._ahead_done)
        else:
            self._search_ahead()

    def drop_from(self, v_top) -> None:
        """Forget the scan speeds at or above ``v_top`` (their searches not started are cancelled)."""
        with self._lock:
            self._scan = {v for v in self._scan if v < v_top}
            self._top = min(self._top, v_top)
            above = [f for (v, _key), f in self._futures.items() if v >= v_top]
        for f in above:  # outside the lock: a cancelled future runs its callbacks here
            f.cancel()
        self._search_ahead()

    def failed_at(self, v) -> None:
        """The speed search failed at ``v``: the final ``v_min`` lies above it, so every scan speed up to it
        will be below the final search's top."""
        with self._lock:
            self._below = max(self._below, v)
        self._search_ahead()

    @property
    def executor(self) -> Executor | None:
        """Where searches run in the background (``None``: here, or after the executor failed)."""
        return self._executor

    def speeds(self) -> list:
        """The scan speeds still wanted, sorted."""
        with self._lock:
            return sorted(self._scan)

    def _search_ahead(self) -> None:
        """Start the next search the final search will ask (as far as known now), unless one is running.

        The scan's bisection over the scan speeds up to the search's fastest failure (they are below the
        final top: the final search bisects the same ones unless a scan speed lies between that failure and
        ``v_min``), then the bisection between its bracket when the bracket's upper end is such a scan
        speed (its questions then do not depend on the final top).
        """
        with self._lock:
            if self._executor is None or self._closed or self._ahead:
                return

            def row(v, key):
                f = self._futures.get((v, key))
                if f is None or not f.done() or f.cancelled() or f.exception() is not None:
                    return None
                return f.result()

            speeds = sorted(u for u in self._scan if u < self._top and u <= self._below)
            found = _scan_question(speeds, lambda v: None if row(v, None) is None else bool(row(v, None).verified))
            if not isinstance(found, tuple):
                v, key, warm = found, None, self._warm
            else:
                lo, hi = found
                if lo < 0 or hi >= len(speeds):
                    return  # nothing refuted, or the bracket ends at the final top: not known yet
                step = _fine_question((speeds[lo], None), speeds[hi], self._tol, row)
                if step[0] is None:
                    return
                v, key = step
                warm = verified_counterexample(row(*key))
            if (v, key) in self._futures and not self._futures[(v, key)].cancelled():
                return  # the needed search failed on the executor: result() deals with that
            self._ahead = True
            future = self._futures[(v, key)] = self._executor.submit(refute_speed, *self._args, v, warm=warm)
        future.add_done_callback(self._ahead_done)

    def _ahead_done(self, future) -> None:
        with self._lock:
            self._ahead = False
        if not future.cancelled() and future.exception() is None:
            self._search_ahead()

    def result(self, v, warm=None, key=None):
        """The search at speed ``v``: the executor's result, or a run here if the executor failed.

        ``warm`` (a verified counterexample at a neighbouring speed, named by ``key``: the same key, the
        same start) starts the search; without it, the refuter's own.
        """
        if warm is None:
            warm = self._warm
        if (v, key) not in self._rows:
            if self._closed:
                raise CancelledError("the counterexample searches were stopped")
            row = None
            if self._executor is not None:
                with self._lock:
                    future = self._futures.get((v, key))
                    if future is None or future.cancelled():
                        future = self._futures[(v, key)] = self._executor.submit(refute_speed, *self._args, v,
                                                                                 warm=warm)
                try:
                    row = future.result()
                except Exception as exc:
                    if self._closed:  # stopped by close() (an interrupt): no search here either
                        raise CancelledError("the counterexample searches were stopped") from None
                    # e.g. a robot defined in a script the worker cannot import: go on here (a
                    # genuine error of the search is raised again by the run here), possibly on
                    # the helper thread, so with a model of its own (CasADi functions are not to
                    # be called from two threads at once)
                    log.warning("background counterexample search failed (%r); searching in this process", exc)
                    self._stop_executor()
                    self._executor = None
                    self._kin = None
            self._rows[(v, key)] = row if row is not None else refute_speed(*self._args, v, kin=self._kin,
                                                                            warm=warm)
        return self._rows[(v, key)]

    def close(self) -> None:
        """Cancel what has not started, start nothing more; shut the executor down if this object made it."""
        self._closed = True
        self._stop_executor()

    def _stop_executor(self) -> None:
        with self._lock:
            futures = list(self._futures.values())
        for f in futures:
            f.cancel()
        if self._own and self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)


def _scan_question(speeds: list, refuted):
    """The scan's bisection over ``speeds`` (sorted) with answers ``refuted(v)`` (True, False or None: not known).

    Returns ``(lo, hi)``, the indices of the fastest refuted speed (-1: none) and of the slowest speed
    not refuted above it (``len(speeds)``: none, the top), when every answer needed is known; else the
    first speed whose answer is needed.  The slowest speed is asked before none is declared refuted.
    """
    lo, hi = -1, len(speeds)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        answer = refuted(speeds[mid])
        if answer is None:
            return speeds[mid]
        lo, hi = (mid, hi) if answer else (lo, mid)
    return lo, hi


def _fine_question(ok: tuple, v_no: float, tol: float, row) -> tuple:
    """The bisection between the fastest refuted speed and ``v_no`` to ``tol`` with rows ``row(v, key)`` (None:
    not known), each step keyed by the chain of refuted speeds that starts it: ``ok = (speed, its key)``.

    Returns ``(speed, key)``, the first step whose row is needed, or ``(None, ok)`` with the final ``ok``.
    """
    while v_no - ok[0] > tol:
        mid = round(0.5 * (ok[0] + v_no), 6)
        if mid in (ok[0], v_no):  # tol below the rounding of speeds
            break
        r = row(mid, ok)
        if r is None:
            return mid, ok
        if r.verified:
            ok = (mid, ok)
        else:
            v_no = mid
    return None, ok


def refutation_search(refuter: Refuter, v_top, tol):
    """Refutation bound below ``v_top``: the largest speed with a verified counterexample.

    The coarse scan's speeds (0.1 m/s from 0.3 m/s, or the caller's) below
    ``v_top`` are bisected (a speed refuted, the next faster not) rather
    than all searched, then the speeds between the fastest refuted and the
    slowest non-refuted speed above it (or ``v_top``) are bisected to
    ``tol``, each step warm-started from the fastest refuted speed's
    counterexample.  Each speed is searched against its own plan's readings
    and ``a_max`` (the bounds its certificate would use); a failed search
    proves nothing (the NLP is non-convex).  Both bisections presume that a
    counterexample exists below a refuted speed; when that fails, the bound
    is still a speed with a verified counterexample, only a faster refuted
    speed may have been missed.

    Returns
    -------
    bound : float or None
    rows : list of planner.refute.SpeedRefutation (sorted by speed): the speeds searched
    """
    speeds = [v for v in refuter.speeds() if v < v_top]
    rows = {}

    def refuted(v) -> bool:
        rows[v] = refuter.result(v)
        return bool(rows[v].verified)

    lo, hi = _scan_question(speeds, refuted)
    if lo < 0:
        return None, [rows[v] for v in sorted(rows)]
    keyed = {(v, None): r for v, r in rows.items()}

    def step(v, key):
        # each step starts from the counterexample of the fastest refuted speed before it (named by its chain)
        keyed[(v, key)] = rows[v] = refuter.result(v, warm=verified_counterexample(keyed[key]), key=key)
        return rows[v]

    _none, ok = _fine_question((speeds[lo], None), speeds[hi] if hi < len(speeds) else v_top, tol, step)
    return ok[0], [rows[v] for v in sorted(rows)]
