"""Monte Carlo confirmation of a certificate: simulated executions tracked as at run time.

Each execution draws a true geometry in ``[xi]``, follows the plan's
Cartesian path with the true IK, reads the joints through a quantising
encoder (:func:`planner.simulate.quantise`) and is tracked by the run-time
tracker.  The counts say how often the run-time tracker detects the change
on executions the certificate covers; containment failures and wrong
verdicts must be zero (they would be bugs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from robots import validators as V
from verifier.tracker import TrackerSettings, Verdict, initial_box_from_mode, track_batch

from . import execution as ex_
from .certify import execution_class
from .plan import derived_a_max
from .simulate import Quantisation, quantise, random_geometry
from .task import PlannedTrajectory, PlanningBounds

__all__ = ["RunRecord", "MonteCarloResult", "monte_carlo_confirmation"]

#: Readings cycle through the encoder models run by run.
_KINDS = (Quantisation.FLOOR, Quantisation.ROUND, Quantisation.UNIFORM)


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

    def summary(self) -> dict:
        """JSON-ready form."""
        return {
            "runs": self.runs, "seed": self.seed, "detected": self.detected, "in_class": self.in_class,
            "detected_in_class": self.detected_in_class, "outside_class": list(self.outside_class),
            "containment_failures": list(self.containment_failures),
            "wrong_verdicts": [w.summary() for w in self.wrong_verdicts],
            "not_detected": [w.summary() for w in self.not_detected],
        }


def monte_carlo_confirmation(kin, imodel, plan: PlannedTrajectory, bounds: PlanningBounds, *, runs=50, seed=0,
                             a_max=None, progress=None, execution: ex_.ExecutionClass | None = None
                             ) -> MonteCarloResult:
    """Execute ``plan``'s Cartesian motion with random true geometries and quantisations.

    Each execution: geometry uniform in ``[xi]`` (every 5th at a random corner),
    joints by the true IK, readings quantised (floor, round or a uniform
    random error within ``eps_q``), tracked by the run-time tracker (robot
    defaults, ``a_max`` of the certificate).  Each execution is checked
    against the certificate's class ``execution`` (derived from ``bounds``
    when not given).

    Returns
    -------
    MonteCarloResult
    """
    runs = int(V.number("runs", runs, lo=1))
    robot = kin.robot
    b = bounds.resolved(robot)
    a_max = derived_a_max(plan, b) if a_max is None else a_max
    cls = execution_class(kin, plan, b) if execution is None else execution
    s = TrackerSettings.for_robot(robot, t_s=b.t_s, eps_q=b.eps_q, a_max=a_max, xi_splits=b.xi_splits)
    rng = np.random.default_rng(seed)
    qs, truths = [], []
    for r in range(runs):
        xi = random_geometry(robot, rng, corners=(r % 5 == 4))
        q_true = kin.ik_path(plan.x, xi, plan.q[0])
        q_read = quantise(q_true, b.eps_q, _KINDS[r % len(_KINDS)], rng)
        modes = kin.mode_batch(plan.x, q_true, xi)
        qs.append(q_read)
        truths.append((xi, modes, ex_.in_class(cls, robot, q_true, plan.q, xi, plan.xi_plan, b.eps_q,
                                               b.tracking_error)))
    q = np.stack(qs)
    m0 = int(truths[0][1][0])
    boxes = [initial_box_from_mode(imodel, q[r, 0], m0, s) for r in range(runs)]
    x0 = (np.array([bx[0] for bx in boxes]), np.array([bx[1] for bx in boxes]))
    res, rec = track_batch(imodel, q, s, x0, record=True, progress=progress)
    misses, failures, wrong = [], [], []
    for r in range(runs):
        inside = (np.all(rec["x_lo"][r] <= plan.x) and np.all(plan.x <= rec["x_hi"][r])
                  and np.all(rec["xd_lo"][r, 1:] <= plan.xd[1:]) and np.all(plan.xd[1:] <= rec["xd_hi"][r, 1:]))
        if not inside:
            misses.append(r)
        modes = truths[r][1]
        certified = rec["mode"][r] != 0
        true_changed = modes[-1] != modes[0]
        bad_mode = bool(np.any(rec["mode"][r][certified] != modes[certified]))
        if bad_mode or (res.verdict[r] is Verdict.MODE_CHANGED and not true_changed):
            wrong.append(RunRecord(r, res.verdict[r], truths[r][0]))
        elif res.verdict[r] is not Verdict.MODE_CHANGED:
            failures.append(RunRecord(r, res.verdict[r], truths[r][0]))
    admissible = [r for r in range(runs) if truths[r][2]]
    return MonteCarloResult(
        runs=runs,
        seed=seed,
        detected=int(sum(v is Verdict.MODE_CHANGED for v in res.verdict)),
        in_class=len(admissible),
        detected_in_class=int(sum(res.verdict[r] is Verdict.MODE_CHANGED for r in admissible)),
        outside_class=tuple(r for r in range(runs) if not truths[r][2]),
        containment_failures=tuple(misses),
        wrong_verdicts=tuple(wrong),
        not_detected=tuple(failures),
    )
