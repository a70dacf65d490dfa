"""Monte Carlo confirmation of a certificate: simulated executions tracked as at run time.

Each execution draws a true geometry in ``[xi]``, follows the plan's
Cartesian path with the true IK, reads the joints through a quantising
encoder (:func:`planner.simulate.quantise`) and is tracked by the run-time
tracker.  The counts say how often the run-time tracker detects the change
on executions the certificate covers; containment failures and wrong
verdicts must be zero (they would be bugs).
"""

from __future__ import annotations

import logging
import threading
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError
from crosscert.verifier.settings import TrackerSettings, Verdict
from crosscert.verifier.tracker import initial_box_from_mode, track_batch
from crosscert.verifier.window import Reasoning, track_window

from . import execution as ex_
from .execution_proof import execution_class
from .models import interval_model, kinematic_model
from .simulate import Quantisation, quantise, random_geometry
from .task import PlannedTrajectory, PlanningBounds, ResolvedBounds, resolved

__all__ = ["RunRecord", "MonteCarloResult", "monte_carlo_confirmation", "monte_carlo_runs", "merge_results", "BATCH_RUNS"]

log = logging.getLogger(__name__)

#: Readings cycle through the encoder models run by run.
_KINDS = (Quantisation.FLOOR, Quantisation.ROUND, Quantisation.UNIFORM)
#: Geometry sub-boxes per hypothesis in the window passes of an execution (``window`` reasoning).
MC_WINDOW_GEOMETRIES = 16


@dataclass(frozen=True, eq=False)
class RunRecord:
    """One execution worth a look: its index, the run-time verdict and its true geometry ``xi`` (m)."""

    run: int
    verdict: Verdict
    xi: np.ndarray

    def summary(self) -> dict:
        """JSON-ready form."""
        return {"run": self.run, "verdict": self.verdict.value, "xi": [float(v) for v in self.xi]}


@dataclass(frozen=True)
class MonteCarloResult:
    """Counts of a Monte Carlo confirmation.

    Attributes
    ----------
    runs, seed : int
    detected : int
        Executions the run-time tracker reports ``mode-changed``.
    in_class, detected_in_class : int
        Executions inside the certificate's class, and those detected among them.
    outside_class : tuple of int
        Indices of executions outside the class.
    containment_failures : tuple of int
        Indices whose boxes missed the truth (a bug if not empty).
    wrong_verdicts : tuple of RunRecord
        Certified modes or verdicts contradicting the truth (a bug if not empty).
    not_detected : tuple of RunRecord
        Executions whose change the run-time tracker did not certify.
    envelope_checked : bool
        Whether each execution's readings were also checked against the certificate's envelope, as
        ``monitor --certificate`` checks them (:mod:`planner.certify.envelope`).
    covered_at_run_time : int
        Executions whose readings stay in the envelope up to the certified decision: the certificate's
        verdict holds for them at run time, whatever the tracker says (0 when not checked).
    left_envelope : tuple of dict
        The others: where each one's readings left (``run``, ``sample``, ``joint`` 1-based, ``excess`` in the
        joint's unit, ``check``).
    """

    runs: int
    seed: int
    detected: int
    in_class: int
    detected_in_class: int
    outside_class: tuple
    containment_failures: tuple
    wrong_verdicts: tuple
    not_detected: tuple
    envelope_checked: bool = False
    covered_at_run_time: int = 0
    left_envelope: tuple = ()

    def summary(self) -> dict:
        """JSON-ready form."""
        return {
            "envelope_checked": self.envelope_checked,
            "covered_at_run_time": self.covered_at_run_time if self.envelope_checked else None,
            "left_envelope": list(self.left_envelope),
            "runs": self.runs, "seed": self.seed, "detected": self.detected, "in_class": self.in_class,
            "detected_in_class": self.detected_in_class, "outside_class": list(self.outside_class),
            "containment_failures": list(self.containment_failures),
            "wrong_verdicts": [w.summary() for w in self.wrong_verdicts],
            "not_detected": [w.summary() for w in self.not_detected],
        }


#: Largest joint change (rad; m for a prismatic joint) from the planned joints that a geometry of the box may cause on the same
#: leg branch (the calibration boxes move joints by milliradians; another branch is radians away).
_SAME_BRANCH = 0.2
#: Executions per task when an executor is given: ~1-2 s of tracking per task on one core.
BATCH_RUNS = 200
#: Executions per share when a background worker takes part (``beside``): the shares are taken one at a
#: time from both ends, so neither process waits for the other longer than one share (an execution the
#: window passes decide costs 0.1-4 s on the benchmark task).
BESIDE_CHUNK = 1


def monte_carlo_confirmation(kin, imodel, plan: PlannedTrajectory, bounds: PlanningBounds | ResolvedBounds, *,
                             runs=50, seed=0, progress=None, execution: ex_.ExecutionClass | None = None,
                             executor: Executor | None = None, batch_runs: int = BATCH_RUNS,
                             parallel: bool = True, beside: Executor | None = None,
                             envelope=None) -> MonteCarloResult:
    """Execute ``plan``'s Cartesian motion with random true geometries and quantisations.

    Each execution ``r``: geometry uniform in ``[xi]`` (every 5th at a random
    corner), joints by the true IK, readings quantised (floor, round or a
    uniform random error within ``eps_q``, in turn), tracked by the run-time
    tracker under the certificate's bounds (:meth:`~planner.task.ResolvedBounds.tracker_settings`: its
    ``eps_q``, ``t_s``, initial speed ``xd0`` and the plan's ``a_max``, the robot's ``[xi]``) from the plan's
    initial mode, with window passes where it is undecided when
    ``bounds.reasoning`` is ``window``.  Each execution is checked against the certificate's class
    ``execution`` (derived from ``bounds`` when not given).  Execution ``r``
    draws from its own generator ``default_rng([seed, r])``, so the result does
    not depend on how the runs are split.

    Parameters
    ----------
    bounds : ResolvedBounds or PlanningBounds
        Resolved for ``kin.robot`` (for ``plan`` or not: :meth:`~planner.task.ResolvedBounds.for_plan`, whose
        ``a_max`` and ``xd0`` the tracker assumes), or resolved here (:func:`planner.task.resolved`).
    executor : concurrent.futures.Executor, optional
        Run the executions in batches of ``batch_runs`` on it (a process pool,
        a Dask client's ``get_executor()``): for 10^5 executions and more.
        Each worker builds the robot's models once.
    envelope : planner.certify.envelope.CertifiedEnvelope, optional
        The certificate's run-time envelope: each execution's readings are checked against it too
        (``covered_at_run_time``).
    beside : concurrent.futures.Executor, optional
        Without ``executor``: share the executions with it (a certification's background worker, idle for
        part of the run): it takes :data:`BESIDE_CHUNK` executions at a time from the first ones (serial
        kernels), one call in flight, while this process takes them from the last ones, until the two
        meet (:func:`_shared`).  If it fails, the executions it had not done run here.
    progress : callable or planner.progress.Progress, optional
        Counts samples of the forward pass; with ``beside``, executions (one call each).

    Returns
    -------
    MonteCarloResult
    """
    runs = int(V.number("runs", runs, lo=1))
    batch_runs = int(V.number("batch_runs", batch_runs, lo=1))
    robot = kin.robot
    b = resolved(bounds, robot).for_plan(plan)
    cls = execution_class(kin, plan, b) if execution is None else execution
    s = b.tracker_settings()  # the run-time tracker under the certificate's bounds (its xd0, the plan's a_max)
    if executor is None and beside is None:
        return monte_carlo_runs(robot, plan, b, s, cls, seed, 0, runs, models=(kin, imodel), progress=progress,
                                parallel=parallel, envelope=envelope)
    if executor is None:
        def there(start, stop):
            return beside.submit(monte_carlo_runs, robot, plan, b, s, cls, seed, start, stop, parallel=False,
                                 envelope=envelope)

        def here(start, stop):
            return monte_carlo_runs(robot, plan, b, s, cls, seed, start, stop, models=(kin, imodel),
                                    parallel=parallel, envelope=envelope)

        return merge_results(_shared(there, here, runs, BESIDE_CHUNK, progress))
    futures = [executor.submit(monte_carlo_runs, robot, plan, b, s, cls, seed, start, min(runs, start + batch_runs),
                               envelope=envelope)
               for start in range(0, runs, batch_runs)]
    return merge_results([f.result() for f in futures])


def monte_carlo_runs(robot, plan: PlannedTrajectory, b: ResolvedBounds, settings: TrackerSettings,
                     cls: ex_.ExecutionClass, seed: int, start: int, stop: int, *, models=None,
                     progress=None, parallel: bool = True, envelope=None) -> MonteCarloResult:
    """Executions ``start .. stop - 1`` of a Monte Carlo confirmation (module-level: any executor can run it).

    ``b`` are the bounds resolved for the robot (``PlanningBounds.resolve``); ``models`` the robot's ``(KinematicModel,
    IntervalModel)``, those this thread keeps when absent (:mod:`planner.models`); ``envelope`` the
    certificate's run-time envelope, any object with ``check(q)`` (:mod:`planner.certify.envelope`).
    """
    kin, imodel = (kinematic_model(robot), interval_model(robot)) if models is None else models
    m0 = int(kin.mode(plan.x[0], plan.q[0], plan.xi_plan))
    qs, truths = [], []
    for r in range(start, stop):
        rng = np.random.default_rng([seed, r])
        xi = random_geometry(robot, rng, corners=(r % 5 == 4))
        q_true = _true_joints(kin, plan, xi)
        q_read = quantise(q_true, b.eps_q, _KINDS[r % len(_KINDS)], rng)
        modes = kin.mode_batch(plan.x, q_true, xi)
        qs.append(q_read)
        truths.append((xi, modes, ex_.in_class(cls, robot, q_true, plan.q, xi, plan.xi_plan, b.eps_q,
                                               b.tracking_error)))
    q = np.stack(qs)
    boxes = [initial_box_from_mode(imodel, q[i, 0], m0, settings) for i in range(len(qs))]
    x0 = (np.array([bx[0] for bx in boxes]), np.array([bx[1] for bx in boxes]))
    res, rec = track_batch(imodel, q, settings, x0, record=True, progress=progress, parallel=parallel)
    verdicts = list(res.verdict)
    if b.reasoning is Reasoning.WINDOW:
        # the forward boxes are checked for containment below; the window decides what they left open
        for i in range(len(qs)):
            if verdicts[i] is Verdict.UNKNOWN:
                verdicts[i] = track_window(imodel, q[i], settings, x0=(x0[0][i], x0[1][i]),
                                           max_geometries=MC_WINDOW_GEOMETRIES, parallel=parallel,
                                           goal=Verdict.MODE_CHANGED, one_motion=b.one_motion).verdict
    misses, failures, wrong = [], [], []
    for i, r in enumerate(range(start, stop)):
        # from the first sample on: a start faster than the initial box (xd0) is a containment failure there
        inside = (np.all(rec["x_lo"][i] <= plan.x) and np.all(plan.x <= rec["x_hi"][i])
                  and np.all(rec["xd_lo"][i] <= plan.xd) and np.all(plan.xd <= rec["xd_hi"][i]))
        if not inside:
            misses.append(r)
        modes = truths[i][1]
        certified = rec["mode"][i] != 0
        true_changed = modes[-1] != modes[0]
        bad_mode = bool(np.any(rec["mode"][i][certified] != modes[certified]))
        wrong_verdict = ((verdicts[i] is Verdict.MODE_CHANGED and not true_changed)
                         or (verdicts[i] is Verdict.MODE_UNCHANGED and true_changed)
                         or verdicts[i] is Verdict.INCONSISTENT)
        if bad_mode or wrong_verdict:
            wrong.append(RunRecord(r, verdicts[i], truths[i][0]))
        elif verdicts[i] is not Verdict.MODE_CHANGED:
            failures.append(RunRecord(r, verdicts[i], truths[i][0]))
    admissible = [i for i in range(len(qs)) if truths[i][2]]
    left = []
    for i, r in enumerate(range(start, stop)):
        st = envelope.check(q[i]) if envelope is not None else None
        if st is not None and not st.holds:
            where = st.summary()
            left.append({"run": r, "sample": where["left_at_sample"], "joint": where["joint"],
                         "excess": where["excess"], "check": where["check"]})
    return MonteCarloResult(
        runs=stop - start,
        seed=seed,
        detected=int(sum(v is Verdict.MODE_CHANGED for v in verdicts)),
        in_class=len(admissible),
        detected_in_class=int(sum(verdicts[i] is Verdict.MODE_CHANGED for i in admissible)),
        outside_class=tuple(r for i, r in enumerate(range(start, stop)) if not truths[i][2]),
        containment_failures=tuple(misses),
        wrong_verdicts=tuple(wrong),
        not_detected=tuple(failures),
        envelope_checked=envelope is not None,
        covered_at_run_time=0 if envelope is None else stop - start - len(left),
        left_envelope=tuple(left),
    )


def _true_joints(kin, plan: PlannedTrajectory, xi) -> np.ndarray:
    """Joints (K, n) of geometry ``xi`` along the plan's poses: one batched Newton from the planned joints,
    the plan's branch kept (continuation along the path where a pose does not converge close to it)."""
    q, ok = kin.ik_batch(plan.x, xi, plan.q)
    if ok.all() and np.max(np.abs(q - plan.q)) <= _SAME_BRANCH:
        return q
    return kin.ik_path(plan.x, xi, plan.q[0])


def _shared(there, here, runs: int, chunk: int, progress=None) -> list:
    """The results of executions ``0 .. runs - 1`` in chunks of ``chunk``, in execution order, shared between
    ``there(start, stop)`` (a future: another process) and ``here(start, stop)`` (a result, this thread).

    A feeder thread keeps one chunk in flight there, taken from the front, while this thread takes chunks
    from the back; each side takes the next chunk only when its last one is done, so the two finish within
    one chunk of each other whatever the executions cost.  The chunks there failed on, and those it would
    have taken after, run here.  ``progress`` is called once per execution done, from this thread.
    """
    bounds = [(start, min(runs, start + chunk)) for start in range(0, runs, chunk)]
    results = [None] * len(bounds)
    lock = threading.Lock()
    front, back, done_there = 0, len(bounds), []

    def feed():
        nonlocal front
        while True:
            with lock:
                if front >= back:
                    return
                i = front
                front += 1
            try:
                results[i] = there(*bounds[i]).result()
            except Exception as exc:  # the worker failed: its chunk and the rest run here (the same draws)
                log.warning("background Monte Carlo executions failed (%r); running them in this process", exc)
                return
            with lock:
                done_there.append(i)

    def tick(chunks):
        if progress is not None:
            for i in chunks:
                for _ in range(*bounds[i]):
                    progress(1)

    feeder = threading.Thread(target=feed, name="crosscert-monte-carlo-feeder", daemon=True)
    feeder.start()
    try:
        while True:
            with lock:
                if back <= front:
                    break
                back -= 1
                i = back
                seen, done_there[:] = list(done_there), []
            tick(seen)
            results[i] = here(*bounds[i])
            tick([i])
    finally:  # on an error here too: the feeder takes no further chunk
        with lock:
            back = min(back, front)
    feeder.join()
    tick(done_there)
    for i, r in enumerate(results):
        if r is None:
            results[i] = here(*bounds[i])
            tick([i])
    return results


def merge_results(parts: list[MonteCarloResult]) -> MonteCarloResult:
    """One result from the results of consecutive batches of runs (counts added, lists joined)."""
    if not parts:
        raise InputError("no Monte Carlo batches to merge")
    return MonteCarloResult(
        runs=sum(p.runs for p in parts), seed=parts[0].seed, detected=sum(p.detected for p in parts),
        in_class=sum(p.in_class for p in parts), detected_in_class=sum(p.detected_in_class for p in parts),
        outside_class=tuple(r for p in parts for r in p.outside_class),
        containment_failures=tuple(r for p in parts for r in p.containment_failures),
        wrong_verdicts=tuple(w for p in parts for w in p.wrong_verdicts),
        not_detected=tuple(w for p in parts for w in p.not_detected),
        envelope_checked=all(p.envelope_checked for p in parts),
        covered_at_run_time=sum(p.covered_at_run_time for p in parts),
        left_envelope=tuple(w for p in parts for w in p.left_envelope),
    )
