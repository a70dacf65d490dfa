"""What a certification promises, as data: :class:`CrossingCertificate` and its JSON (``certificate.json``).

The orchestration that makes one is :func:`planner.certify.crossing.certify_crossing` (a task) or
:mod:`planner.certify.trajectory` (a user's plan); this module holds only the schema, its summary and
the versions it records.
"""

from __future__ import annotations

import importlib.metadata as md
from dataclasses import dataclass, field


from crosscert.verifier.settings import Verdict
from crosscert.verifier.tracker import TrackResult
from crosscert.verifier.window import WindowResult

from .. import execution as ex_
from .. import refute
from ..acceleration import AccelerationAssumption
from ..bounce import BounceGap
from ..montecarlo import MonteCarloResult
from ..task import CrossingTask, PlannedTrajectory, ResolvedBounds
from .plan import decision_sample

__all__ = ["CrossingCertificate", "CERTIFICATE_SCHEMA", "package_versions"]

#: Version of the layout of :meth:`CrossingCertificate.summary` (``certificate.json``).
CERTIFICATE_SCHEMA = "crosscert-certificate/4"

@dataclass(frozen=True)
class CrossingCertificate:
    """Result of :func:`certify_crossing` (frozen).

    ``verdict`` is ``MODE_CHANGED`` when ``v_min`` exists (the change is
    certified for every admissible execution at ``v_min``), ``UNKNOWN`` when
    no tried speed certifies.  ``refutation_bound`` (m/s, or None when not
    computed / no counterexample) is the largest speed at which a verified
    counterexample exists: no sound tracker can certify at or below it.
    ``execution`` is the class of admissible executions the certificate
    covers (:mod:`planner.execution`); ``timings_s`` the wall time of each
    phase, s (``setup``, ``search``, ``certificate`` (0 since the search's run is the certificate), ``monte_carlo``,
    ``refutation``: the wait for the background searches left after the
    Monte Carlo run, and ``bounce``: the bounce search's own run time, which
    overlaps the other phases when it ran in the background worker).
    ``robot_name``, ``param_names`` (of the geometry vector ``xi``) and
    ``task`` say what was certified.  ``enclosures`` is the
    forward tracker's run at ``v_min``; ``window`` the window passes on the
    same inputs when the forward run alone did not certify (their verdict is
    then the certificate's).  ``bounce`` brackets, at ``v_min``, the turn-back
    distance from which the task's failed crossings are certified
    ``mode-unchanged`` against the crossing floor (:mod:`planner.bounce`;
    computed with the refutation bound).  ``a_max_used`` is the acceleration
    bound of every pose axis with its unit and source
    (:mod:`planner.acceleration`), ``acceleration_units`` the robot's unit of
    each axis' acceleration, ``joint_units`` and ``pose_units`` those of the
    joints (``eps_q``, ``tracking_error``, the execution class) and of the pose axes; ``at_robot_a_max`` the same search under
    the robot's physical ``a_max`` (:func:`planner.assumption_cost.certify_at_robot_a_max`;
    None when not asked for).
    """

    verdict: Verdict
    v_min: float | None
    refutation_bound: float | None
    trials: tuple
    trajectory: PlannedTrajectory | None
    enclosures: TrackResult | None
    bounds: ResolvedBounds
    a_max_used: AccelerationAssumption | None
    monte_carlo: MonteCarloResult | None
    versions: dict
    elapsed_s: float
    refutation: tuple = field(default=(), repr=False)
    execution: ex_.ExecutionClass | None = None
    timings_s: dict = field(default_factory=dict)
    robot_name: str = ""
    param_names: tuple = ()
    task: CrossingTask | None = field(default=None, repr=False)
    window: WindowResult | None = field(default=None, repr=False)
    bounce: BounceGap | None = field(default=None, repr=False)
    at_robot_a_max: object = field(default=None, repr=False)
    acceleration_units: tuple = ()
    joint_units: tuple = ()
    pose_units: tuple = ()
    refutation_ran: bool = False
    plan_source: object = None  # planner.certify.trajectory.PlanSource of a given plan; None: planned here

    @property
    def refutation_search(self) -> refute.SearchCompleteness | None:
        """What ``refutation_bound`` rests on (:class:`planner.refute.SearchCompleteness`); None: not run."""
        return refute.completeness(self.refutation) if self.refutation_ran else None

    @property
    def certified_below_v_min(self) -> list:
        """Tried speeds below ``v_min`` that certified (m/s): where certification was not monotone in the speed."""
        if self.v_min is None:
            return [t.v_sing for t in self.trials if t.verdict is Verdict.MODE_CHANGED]
        return [t.v_sing for t in self.trials if t.verdict is Verdict.MODE_CHANGED and t.v_sing < self.v_min]

    @property
    def v_min_at_lower_end(self) -> bool:
        """``v_min`` is the slowest speed tried: a smaller one may certify too (lower ``v_low``)."""
        if self.v_min is None or self.plan_source is not None:  # a given plan has one speed, searched nowhere
            return False
        return self.v_min <= min(t.v_sing for t in self.trials)

    def certified_run(self) -> dict | None:
        """What a run-time check of an execution needs (:mod:`planner.certify.envelope`): the sample at which
        the certifying run decided (its forward pass's streak start, else the plan's last sample: the window
        passes read the whole run) and the initial and final modes; None without a decided certificate."""
        if self.enclosures is None or self.trajectory is None or self.verdict not in (Verdict.MODE_CHANGED,
                                                                                       Verdict.MODE_UNCHANGED):
            return None
        e = self.enclosures
        at, by = decision_sample(e, self.verdict, len(self.trajectory.q))
        final = -e.initial_mode if self.verdict is Verdict.MODE_CHANGED else e.initial_mode
        return {"decided_at_sample": at, "decided_by": by, "initial_mode": int(e.initial_mode),
                "final_mode": int(final)}

    def _named(self, xi) -> dict | None:
        """A geometry vector as ``{parameter name: value}`` (SI)."""
        if xi is None:
            return None
        names = self.param_names or tuple(f"xi{i + 1}" for i in range(len(xi)))
        return {k: float(v) for k, v in zip(names, xi)}

    def summary(self) -> dict:
        """JSON-ready, self-describing report (schema :data:`CERTIFICATE_SCHEMA`; docs/file-formats.md)."""
        b = self.bounds
        at = self.at_robot_a_max
        execution = None
        if self.execution is not None:
            execution = self.execution.summary()
            execution["xi_lo"] = self._named(self.execution.xi_lo)
            execution["xi_hi"] = self._named(self.execution.xi_hi)
        return {
            "schema": CERTIFICATE_SCHEMA,
            "robot": self.robot_name,
            "plan": None if self.plan_source is None else self.plan_source.summary(),
            "task": None if self.task is None else {"start": self.task.start.tolist(), "goal": self.task.goal.tolist(),
                                                    "working_guess": self.task.working_guess.tolist()},
            "joint_units": [str(u) for u in self.joint_units],
            "pose_units": [str(u) for u in self.pose_units],
            "acceleration_units": list(self.acceleration_units),
            "method": b.method.value,
            "bounds": {
                "eps_q": b.eps_q, "tracking_error": b.tracking_error, "t_s": b.t_s, "t_rest_s": b.t_rest,
                "a_peak_mps2": b.a_peak,
                "a_max": None if b.a_max_given is None else [{"value": v, "unit": u}
                                                             for v, u in zip(b.a_max_given, self.acceleration_units)],
                "a_margin": b.a_margin, "xi_splits": None if b.xi_splits is None else list(b.xi_splits),
                "execution": b.execution.value, "qd_max": b.qd_max, "qdd_max": b.qdd_max,
                "reasoning": b.reasoning.value, "one_motion_samples": b.one_motion,
            },
            "verdict": self.verdict.value,
            "v_min_mps": self.v_min,
            "refutation_bound_mps": self.refutation_bound,
            "refutation_search": None if self.refutation_search is None else self.refutation_search.value,
            "gap_mps": None if self.v_min is None or self.refutation_bound is None else self.v_min - self.refutation_bound,
            "certified_below_v_min_mps": self.certified_below_v_min,
            "v_min_at_lower_end": self.v_min_at_lower_end,
            "a_max_used": None if self.a_max_used is None else self.a_max_used.summary(),
            "v_min_at_robot_a_max_mps": None if at is None else at.v_min,
            "refutation_bound_at_robot_a_max_mps": None if at is None else at.refutation_bound,
            "at_robot_a_max": None if at is None else at.summary(),
            "execution": execution,
            "trials": [
                {"v_sing_mps": r.v_sing, "verdict": r.verdict.value, "forward_verdict": r.forward_verdict.value,
                 "max_width_pose_m": r.max_width_pose,
                 "max_width_velocity_mps": r.max_width_velocity,
                 "certified_at_step": r.certified_at_step}
                for r in self.trials
            ],
            "refutation": [
                {"v_sing_mps": r.speed, "counterexample": bool(r.verified), "outcome": r.outcome.value,
                 "solver_status": r.status, "geometry": self._named(r.geometry)}
                for r in self.refutation
            ],
            "window": None if self.window is None else self.window.summary(),
            "certified_run": self.certified_run(),
            "bounce": None if self.bounce is None else self.bounce.summary(),
            "monte_carlo": None if self.monte_carlo is None else self.monte_carlo.summary(),
            "versions": self.versions,
            "elapsed_s": self.elapsed_s,
            "timings_s": self.timings_s,
        }


def package_versions() -> dict:
    """Versions of crosscert and of the packages its numbers depend on (None: not installed)."""
    out = {}
    for pkg in ("crosscert", "numpy", "casadi", "numba", "scipy"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = None
    return out


