"""The whole certification of a crossing: speed search, certificate, Monte Carlo, refutation bound.

:func:`certify_crossing` bisects the speed, each speed planned and certified
alone (:mod:`planner.certify`; the run at the slowest certified one is the
certificate), confirms it by Monte Carlo (:mod:`planner.montecarlo`) and,
meanwhile, searches verified counterexamples below it (:mod:`planner.refute`)
on an executor with the ``concurrent.futures`` interface, and brackets the
task's bounces (:mod:`planner.bounce`).  It returns a :class:`CrossingCertificate`.
"""

from __future__ import annotations

import logging
import math
import time
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from crosscert.robots import KinematicModel
from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import Verdict

from ..bounce import bounce_floor, bounce_verdicts, gap_of
from ..montecarlo import monte_carlo_confirmation
from ..plan import speed_ceiling
from ..simulate import random_geometry
from ..path import PathTask
from ..task import CrossingTask, PlanningBounds, ResolvedBounds, crossing_on_segment, resolved
from ..progress import Phase, enter
from ..refute.orchestrate import Refuter, refutation_search, timed
from .certificate import CrossingCertificate, package_versions
from ..worker import SubprocessExecutor
from .plan import search_v_min

__all__ = ["certify_crossing", "REFUTE_TOL_DIVISOR", "scan_speeds", "SCAN_FROM", "SCAN_STEP"]

log = logging.getLogger(__name__)

#: Slowest crossing speed a certification tries by default, m/s.
V_LOW = 0.6
#: The refutation bound is bisected to ``tol / REFUTE_TOL_DIVISOR`` by default (:func:`certify_crossing`'s
#: ``refute_tol``): at ``tol`` alone the bound could sit up to ``tol`` below the fastest refuted speed
#: and the printed ratio ``v_min / bound`` would carry that error (2026-12-04: 0.8438 m/s at 0.01,
#: 0.8484 m/s at 0.001 on the default robot's benchmark task).
REFUTE_TOL_DIVISOR = 10


@dataclass(frozen=True)
class SpeedBracket:
    """The speeds a certification searches: ``v_min`` in ``[v_low, v_high]`` m/s, to ``tol`` m/s, found
    around ``v_guess`` m/s when given (:func:`~planner.certify.plan.search_v_min`)."""

    v_low: float
    v_high: float
    tol: float
    v_guess: float | None = None


@dataclass(frozen=True)
class RefuteOptions:
    """How a certification searches counterexamples (see :func:`certify_crossing`'s parameters)."""

    enabled: bool = True
    speeds: tuple | None = None
    in_background: bool = True
    executor: Executor | None = None
    bounce: bool = True
    warm: object = None  # a verified counterexample starting the scan's searches (planner.refute.Counterexample)
    tol: float | None = None  # resolution of the refutation bound, m/s (certify_crossing's refute_tol, filled in)


@dataclass(frozen=True, eq=False)
class _Job:
    """One certification's fixed inputs: the robot, its models, the task and bounds, the bracket."""

    robot: object
    task: CrossingTask
    b: ResolvedBounds
    kin: KinematicModel
    imodel: IntervalModel
    m0: int
    bracket: SpeedBracket
    threads: bool  # thread slots for the tracking (not beside a background worker)


def certify_crossing(robot, task: CrossingTask, bounds: PlanningBounds | None = None, *, v_low=V_LOW, v_high=None,
                     tol=0.01, monte_carlo_runs=50, refute=True, refute_speeds=None, refute_in_background=True,
                     executor: Executor | None = None, seed=0, progress=None, kin=None,
                     imodel=None, bounce: bool = True, v_guess=None, refute_warm=None,
                     refute_tol=None) -> CrossingCertificate:
    """Minimal certified crossing speed for ``task``, its proof and its refutation bound.

    The steps: the speed search (:func:`~planner.certify.plan.search_v_min`), whose run at ``v_min``
    is the certificate; the counterexample searches below it (:func:`refutation_search`, in the
    background by default) and the bounces at ``v_min``; the Monte Carlo confirmation.

    Parameters
    ----------
    robot : robots.Robot
    task : CrossingTask
    bounds : PlanningBounds, optional
        Resolved for ``robot`` once, here (:meth:`PlanningBounds.resolve`; bounds already resolved for it,
        :class:`~planner.task.ResolvedBounds`, are taken as they are); the certificate keeps them.
    v_low, v_high, tol : float
        Speed bracket and resolution of ``v_min``, m/s (:class:`SpeedBracket`); ``v_high`` defaults
        to (and is capped at) :func:`speed_ceiling`: the fastest crossing the time law allows.
    v_guess : float, optional
        A speed near the expected ``v_min``, m/s (an optimisation script passes the previous
        certificate's ``v_min`` on a nearby task): the speed search brackets ``v_min`` around it
        instead of bisecting ``[v_low, v_high]`` (:func:`~planner.certify.plan.search_v_min`), 2-3
        questions instead of about 9 when it is within ``tol``.  Same guarantee; when certification
        is not monotone in the speed the result may differ from the search without it.
    monte_carlo_runs : int
        Executions simulated at ``v_min`` (0 to skip).
    refute, refute_speeds, refute_in_background, executor, bounce
        The counterexample searches (:class:`RefuteOptions`): whether to search below ``v_min``; the
        speeds of the coarse scan (default :func:`scan_speeds`: every 0.1 m/s from 0.3, or from
        ``v_low`` when lower); on ``executor`` while the speed
        search and the Monte Carlo run go on (default: a
        :class:`~planner.worker.SubprocessExecutor` made for this call; a given one is not shut down)
        or here, afterwards; also the bounces of the task at ``v_min`` (:mod:`planner.bounce`).
    refute_tol : float, optional
        Resolution of the refutation bound, m/s; default ``tol / REFUTE_TOL_DIVISOR`` (a tenth of
        ``tol``).  The ratio ``v_min / bound`` is only as good as the coarser of the two; the bound's
        extra bisection steps (about three counterexample searches) run in the background beside
        the Monte Carlo run, so a finer bound costs little wall time.
    refute_warm : planner.refute.Counterexample, optional
        A verified counterexample of a neighbouring speed under bounds these bounds cover: the start of
        the first attempt of every scan speed's search (:func:`refute_speed`'s ``warm``; a start only,
        every candidate is verified as usual).
    seed : int
        Seed of the Monte Carlo executions and of the counterexample starts.
    progress : planner.progress.Progress or callable, optional
        Told each phase as it begins (speed search, Monte Carlo, counterexample searches, bounce
        search) with its size, then called once per unit done; a plain callable is only called.
    kin, imodel : optional
        The robot's kinematic and interval models (built when absent).
    """
    t0 = time.perf_counter()
    if refute_tol is not None:  # checked before any model is built
        refute_tol = V.positive("refute_tol", refute_tol)
    job = _prepare(robot, task, bounds, v_low, v_high, tol, kin, imodel, threads=not (refute and refute_in_background),
                   v_guess=v_guess)
    refute_tol = job.bracket.tol / REFUTE_TOL_DIVISOR if refute_tol is None else refute_tol
    opts = RefuteOptions(refute, refute_speeds, refute_in_background, executor, bounce, refute_warm, refute_tol)
    refuter, starts = _start_refuter(job, opts, seed)
    clock = _Clock({"setup": time.perf_counter() - t0})
    try:
        search, run, mc, ref_bound, ref, gap = _phases(job, task, opts, refuter, starts, monte_carlo_runs, seed,
                                                       progress, clock)
    finally:
        if refuter is not None:
            refuter.close()
    return _certificate(job, search, run, mc, ref_bound, ref, gap, clock.times, t0)


def _phases(job: _Job, task, opts: RefuteOptions, refuter, starts, monte_carlo_runs: int, seed, progress,
            clock: _Clock) -> tuple:
    """The phases of :func:`certify_crossing` once the refuter is started, each timed on ``clock`` (s).

    The speed search, whose run at ``v_min`` is the certificate; the counterexample searches below it and the
    bounces at ``v_min`` started; the Monte Carlo confirmation; then the refutation bound and the bounce gap
    collected.  Returns ``(search, run, mc, ref_bound, ref, gap)`` for :func:`_certificate`.
    """
    t1 = time.perf_counter()
    search = _search(job, refuter, progress)
    t1 = clock.lap("search", t1)
    # the search certified each speed alone, on its own plan, class and a_max: its run at v_min is the
    # certificate (no re-run)
    run = None if search.v_min is None else search.runs[search.v_min]
    t1 = clock.lap("certificate", t1)
    top = search.v_min if search.v_min is not None else max(t.v_sing for t in search.trials)
    ref_job = _refute_below(refuter, top, opts.tol, opts.in_background)
    bounces = None
    # the bounces of a task turn back along its straight segment: a given curved path has none of its own
    if refuter is not None and search.v_min is not None and opts.bounce and not isinstance(task, PathTask):
        bounces = _start_bounces(job, search.v_min, run, refuter, starts)
        t1 = time.perf_counter()  # counted in "bounce", not in the Monte Carlo phase
    mc = _confirm(job, run, monte_carlo_runs, seed, progress, None if refuter is None else refuter.executor)
    t1 = clock.lap("monte_carlo", t1)
    if refuter is not None:
        enter(progress, Phase.REFUTATION, unit="")
    ref_bound, ref = _refutation(refuter, ref_job, top, opts.tol)
    t1 = clock.lap("refutation", t1)
    if bounces is not None:
        enter(progress, Phase.BOUNCE, unit="")
    gap, ran = _bounce_gap(job, bounces, starts)
    clock.lap("bounce", t1)
    if gap is not None:  # its own run time: the tracker's side here plus the crossing searches
        clock.times["bounce"] = bounces[1] + ran
    return search, run, mc, ref_bound, ref, gap


class _Clock:
    """Wall time of each phase of a certification, s (the refutation's is the wait left after the Monte Carlo run)."""

    def __init__(self, times: dict):
        self.times = times

    def lap(self, name: str, since: float) -> float:
        self.times[name] = time.perf_counter() - since
        log.info("certify_crossing: %s done in %.2f s", name, self.times[name])
        return time.perf_counter()


def _prepare(robot, task, bounds, v_low, v_high, tol, kin, imodel, *, threads: bool, v_guess=None) -> _Job:
    """The models, the bounds resolved for the robot, the start's mode and the checked speed bracket."""
    kin = KinematicModel(robot) if kin is None else kin
    imodel = IntervalModel(robot) if imodel is None else imodel
    b = resolved(bounds, robot)  # once: every step of the certification reads these
    m0 = task.m0 if isinstance(task, PathTask) else crossing_on_segment(kin, task, robot.xi_center).m0
    v_feasible = speed_ceiling(kin, task, b)
    v_high = v_feasible if v_high is None else min(float(v_high), v_feasible)
    v_low = V.positive("v_low", v_low)
    tol = V.positive("tol", tol)
    if v_high <= v_low:
        raise InputError(f"no feasible crossing speed above v_low = {v_low} m/s: the {b.method} time law allows "
                         f"at most {v_feasible:.3f} m/s on this task")
    # thread slots for the tracking, unless the counterexample worker runs beside it: it holds the
    # other core, and the serial kernels are as fast then (benchmarks/README.md)
    guess = None if v_guess is None else V.positive("v_guess", v_guess)
    return _Job(robot, task, b, kin, imodel, m0, SpeedBracket(v_low, v_high, tol, guess), threads)


#: The default coarse scan of the counterexample search: every SCAN_STEP m/s from SCAN_FROM m/s (or from
#: ``v_low`` when that is lower) up to ``v_high``; the speeds the search certifies are dropped as it goes.
SCAN_FROM, SCAN_STEP = 0.3, 0.1


def scan_speeds(v_low: float, v_high: float) -> list:
    """The default coarse scan of the counterexample search, m/s (see :data:`SCAN_FROM`): below ``v_low`` when
    ``v_low`` is above 0.3 m/s (a bound below the bracket is still a bound), from ``v_low`` when it is below,
    so that a robot certified slower than 0.3 m/s still has its floor searched."""
    return [round(float(v), 6) for v in np.arange(min(SCAN_FROM, v_low), v_high, SCAN_STEP)]


def _start_refuter(job: _Job, opts: RefuteOptions, seed) -> tuple:
    """The :class:`Refuter` with the coarse scan queued (``None`` without refutation) and its starting geometries."""
    if not opts.enabled:
        return None, None
    robot = job.robot
    # starting geometries of the (non-convex) searches: the box centre and a seeded corner
    starts = [robot.xi_center, random_geometry(robot, np.random.default_rng(seed), corners=True)]
    scan = opts.speeds if opts.speeds is not None else scan_speeds(job.bracket.v_low, job.bracket.v_high)
    try:
        scan = sorted({round(float(v), 6) for v in scan})
    except (TypeError, ValueError):
        raise InputError(f"refute_speeds must be numbers (m/s), got {opts.speeds!r}") from None
    pool = (opts.executor or SubprocessExecutor()) if opts.in_background else None
    refuter = Refuter(robot, job.task, job.b, job.m0, starts, job.kin, pool, own_executor=opts.executor is None,
                      warm=opts.warm, tol=opts.tol)
    refuter.submit(scan)
    return refuter, starts


def _search(job: _Job, refuter, progress):
    """The speed search; a certified speed is the refutation's ceiling (no counterexample is searched at or above),
    a failed one tells it which scan speeds are surely below ``v_min`` (searched ahead of time)."""
    br = job.bracket
    # the bisection asks v_high, then halves the bracket down to tol, then maybe v_low itself; from a
    # guess, typically the guess and one speed tol away (the bar's size is an estimate)
    size = 3 if br.v_guess is not None else 2 + max(0, math.ceil(math.log2((br.v_high - br.v_low) / br.tol)))
    enter(progress, Phase.SEARCH, size, unit="speed")

    def observe(t):
        if refuter is not None:
            if t.verdict is Verdict.MODE_CHANGED:
                refuter.drop_from(t.v_sing)
            else:
                refuter.failed_at(t.v_sing)
        if progress is not None:
            progress(1)

    return search_v_min(job.kin, job.imodel, job.task, job.b, br.v_low, br.v_high, tol=br.tol,
                        observe=observe, parallel=job.threads, v_guess=br.v_guess)


def _refute_below(refuter, top, tol, in_background: bool):
    """Drop the speeds at or above ``top``; in the background, start the refutation search (its future)."""
    if refuter is None:
        return None
    refuter.drop_from(top)
    if not in_background:
        return None
    # the bisection mostly waits on the worker: let it wait beside the Monte Carlo run
    helper = ThreadPoolExecutor(max_workers=1)
    future = helper.submit(refutation_search, refuter, top, tol)
    helper.shutdown(wait=False)
    return future


def _refutation(refuter, ref_job, top, tol):
    """``(bound, rows)`` of the refutation search (its background result, or run here); ``(None, None)`` without."""
    if ref_job is not None:
        return ref_job.result()
    if refuter is not None:
        return refutation_search(refuter, top, tol)
    return None, None


def _start_bounces(job: _Job, v_min, run, refuter, starts) -> tuple:
    """The bounces of the task at ``v_min`` (``run``: the certificate's run there): the tracker's side here
    (this process has the kernels loaded), then the crossing searches on the worker, beside the Monte Carlo
    run.  ``(tracked, seconds, job, bounds)``.

    Both sides assume what the certificate states (its bounds for its own plan: ``a_max``, ``xd0``): a
    bounce certified ``mode-unchanged`` under a narrower assumption than the certificate's would claim more
    than the certificate can.
    """
    b = job.b.for_plan(run.plan)
    tracked, seconds = timed(bounce_verdicts, job.robot, job.task, b, v_min, kin=job.kin,
                             imodel=job.imodel, parallel=job.threads)
    pool = refuter.executor
    floor_job = None if pool is None else pool.submit(timed, bounce_floor, job.robot, job.task, b, tracked,
                                                      starts=starts)
    return tracked, seconds, floor_job, b


def _bounce_gap(job: _Job, bounces, starts) -> tuple:
    """``(gap, seconds of the crossing searches)`` of the started bounces (searched here if the worker failed)."""
    if bounces is None:
        return None, 0.0
    tracked, _seconds, floor_job, b = bounces
    floor = None
    try:
        floor, ran = floor_job.result() if floor_job is not None else (None, 0.0)
    except Exception as exc:  # as for the refutation: a failed worker is no result; run it here
        log.warning("background bounce search failed (%r); searching in this process", exc)
    if floor is None:
        floor, ran = timed(bounce_floor, job.robot, job.task, b, tracked, starts=starts, kin=job.kin)
    return gap_of(tracked, floor), ran


def _confirm(job: _Job, run, runs: int, seed, progress, pool=None):
    """The Monte Carlo confirmation at ``v_min`` (None without a certificate or with 0 runs).

    With the background worker ``pool``, the executions are shared with it one at a time from both ends
    (:func:`planner.montecarlo.monte_carlo_confirmation`, ``beside``): whatever the counterexample and
    bounce searches queued there leave of its time goes to the executions, and neither process waits for
    the other at the end longer than one execution.
    """
    if run is None or not runs:
        return None
    if pool is None:
        enter(progress, Phase.MONTE_CARLO, len(run.plan.q), unit="sample")
    else:
        enter(progress, Phase.MONTE_CARLO, runs, unit="execution")
    return monte_carlo_confirmation(job.kin, job.imodel, run.plan, job.b, runs=runs, seed=seed, progress=progress,
                                    execution=run.execution, parallel=job.threads, beside=pool,
                                    envelope=run.envelope(job.robot, job.b.eps_q))


def _certificate(job: _Job, search, run, mc, ref_bound, ref, gap, clock, t0) -> CrossingCertificate:
    robot = job.robot
    enc = None if run is None else run.forward
    win = None if run is None else run.window
    return CrossingCertificate(
        verdict=(win or enc).verdict if enc is not None else Verdict.UNKNOWN,
        v_min=search.v_min,
        refutation_bound=ref_bound,
        trials=tuple(search.trials),
        trajectory=None if run is None else run.plan,
        enclosures=enc,
        bounds=job.b,
        a_max_used=None if run is None else run.acceleration,
        monte_carlo=mc,
        versions=package_versions(),
        elapsed_s=time.perf_counter() - t0,
        refutation=tuple(ref or ()),
        execution=None if run is None else run.execution,
        timings_s=clock,
        robot_name=robot.name,
        param_names=tuple(robot.param_names),
        task=job.task,
        window=win,
        bounce=gap,
        acceleration_units=robot.acceleration_units,
        joint_units=robot.joint_units,
        pose_units=robot.pose_units,
        refutation_ran=ref is not None,
    )
