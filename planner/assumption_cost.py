"""What a certificate's acceleration assumption buys: v_min again under the robot's physical ``a_max``.

A certificate's acceleration bounds (:mod:`planner.acceleration`) are the
robot's physical ``a_max`` by default, and tighter on some axes when the user
states so: a tracking margin around the plan (``--a-margin``, a declared
``Robot.tracking_a_margin``) or ``--a-max`` below the robot's.  A tighter
assumption covers fewer executions and can certify a slower crossing; with the
default nothing more runs (the outcome is that the two coincide).
:func:`certify_at_robot_a_max` re-runs :func:`planner.certify.crossing.certify_crossing`
with ``a_max`` = the robot's, so a certificate can state both speeds.

Its cost is kept low: no Monte Carlo confirmation and no bounce search; when
the robot's bound is at least the default on every axis (it covers every
execution the default does) the speed search starts at the default's
``v_min`` and the counterexample scan at its refutation bound, since a
counterexample under the tighter bound is one under the wider bound too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np

from crosscert.verifier.settings import Verdict

from .acceleration import AccelerationAssumption, robot_a_max_assumption
from .certify.certificate import CrossingCertificate
from .certify.crossing import certify_crossing
from .progress import suffixed
from .refute import SearchCompleteness, verified_counterexample

__all__ = ["ComparisonOutcome", "AtRobotAMax", "certify_at_robot_a_max", "compares", "speed_guess"]


class ComparisonOutcome(StrEnum):
    """Whether the certificate was also computed under the robot's ``a_max``, and why not."""

    COMPUTED = "computed"
    COINCIDES = "coincides"  # the certificate's bounds already are the robot's a_max: nothing to compare
    NO_CERTIFICATE = "no-certificate"  # the default assumption certified no speed: nothing to compare with


@dataclass(frozen=True)
class AtRobotAMax:
    """The certificate under the robot's physical ``a_max`` (see :func:`certify_at_robot_a_max`).

    Attributes
    ----------
    outcome : ComparisonOutcome
    a_max : AccelerationAssumption
        The robot's ``a_max`` per axis, with units.
    verdict : Verdict or None
        ``MODE_CHANGED`` when some speed certifies; None when not computed.
    v_min, refutation_bound : float or None
        m/s, as in :class:`planner.certify.certificate.CrossingCertificate`.
    v_low : float or None
        Slowest speed tried, m/s (the default's ``v_min`` when the robot's
        bound covers the default's on every axis).
    v_min_at_lower_end : bool
        ``v_min`` is ``v_low``: a slower speed was not tried.
    elapsed_s : float
        Wall time of the extra run, s.
    """

    outcome: ComparisonOutcome
    a_max: AccelerationAssumption
    verdict: Verdict | None = None
    v_min: float | None = None
    refutation_bound: float | None = None
    v_low: float | None = None
    v_min_at_lower_end: bool = False
    elapsed_s: float = 0.0
    #: What ``refutation_bound`` rests on (:class:`planner.refute.SearchCompleteness`); None: not searched.
    refutation_search: SearchCompleteness | None = None

    def summary(self) -> dict:
        """JSON-ready summary (m/s, s; ``a_max`` per axis with unit and source)."""
        return {"outcome": self.outcome.value, "a_max": self.a_max.summary(),
                "verdict": None if self.verdict is None else self.verdict.value, "v_min_mps": self.v_min,
                "refutation_bound_mps": self.refutation_bound, "v_low_mps": self.v_low,
                "v_min_at_lower_end": self.v_min_at_lower_end, "elapsed_s": self.elapsed_s,
                "refutation_search": None if self.refutation_search is None else self.refutation_search.value}


def _outcome(robot, cert: CrossingCertificate) -> ComparisonOutcome:
    """What :func:`certify_at_robot_a_max` does with ``cert``: compute, or say why not."""
    used = cert.a_max_used
    if used is None or cert.v_min is None:
        return ComparisonOutcome.NO_CERTIFICATE
    if used.same_values(robot_a_max_assumption(robot)):
        return ComparisonOutcome.COINCIDES
    return ComparisonOutcome.COMPUTED


def speed_guess(v_min: float, used: AccelerationAssumption, ref: AccelerationAssumption) -> float:
    """Where ``v_min`` should move under the robot's ``a_max``, m/s: the search's guess (its answer does not depend on it).

    A motion at speed ``v`` turning back at the locus needs ``v**2 / (2 a)`` of room, so the slowest speed whose
    turn-backs the tracker can rule out grows like ``sqrt(a)``: ``v_min`` times the square root of the largest
    ratio of the robot's bound to the certificate's over the axes (dimensionless: each ratio is in one unit).
    A guess only: the search asks the speeds themselves, so a poor guess costs questions, never the answer.
    """
    ratio = max(r / u for r, u in zip(ref.values, used.values))
    return float(v_min) * math.sqrt(max(ratio, 1e-12))


def compares(robot, cert: CrossingCertificate) -> bool:
    """Whether :func:`certify_at_robot_a_max` runs a second certification for ``cert`` (``COMPUTED``)."""
    return _outcome(robot, cert) is ComparisonOutcome.COMPUTED


def certify_at_robot_a_max(robot, task, cert: CrossingCertificate, *, v_low=0.6, v_high=None, tol=0.01,
                           refute=True, seed=0, executor=None, progress=None, kin=None,
                           imodel=None, refute_tol=None) -> CrossingCertificate:
    """``cert`` with :attr:`~planner.certify.certificate.CrossingCertificate.at_robot_a_max` filled in.

    Parameters
    ----------
    robot : robots.Robot
    task : CrossingTask
    cert : CrossingCertificate
        The certificate of ``task`` under its own bounds (``cert.bounds``).
    v_low, v_high, tol, refute, seed, executor, progress, kin, imodel
        As for :func:`planner.certify.crossing.certify_crossing` (the call that made ``cert``).
    refute_tol : float, optional
        Resolution of this bound, m/s; default ``tol``: no Monte Carlo run here hides the extra
        searches a finer bound needs (about 4 s on the default robot's benchmark task, measured
        2026-12-04), and the bound starts from ``cert``'s, already refined.

    Returns
    -------
    CrossingCertificate
        ``cert`` unchanged but for ``at_robot_a_max``: ``COINCIDES`` when its
        bounds equal the robot's ``a_max`` on every axis, ``NO_CERTIFICATE``
        when it certified no speed, else ``COMPUTED`` with the v_min and
        refutation bound of ``certify_crossing`` with ``a_max = robot.a_max``
        (no Monte Carlo, no bounce search).
    """
    ref = robot_a_max_assumption(robot)
    used = cert.a_max_used
    outcome = _outcome(robot, cert)
    if outcome is not ComparisonOutcome.COMPUTED:
        return replace(cert, at_robot_a_max=AtRobotAMax(outcome, ref))
    # the robot's bound covers every execution the default covers: start where the default stopped
    covers = all(r >= u for r, u in zip(ref.values, used.values))
    top = max(t.v_sing for t in cert.trials)  # the fastest speed the default's search tried
    start = max(float(v_low), cert.v_min) if covers and cert.v_min < top else float(v_low)
    known = cert.refutation_bound if covers else None
    scan = np.arange(known, top, 0.1) if refute and known is not None else None
    # ...and the counterexample found there starts every scan speed's search (a start, verified as any)
    warm = None if scan is None else next((verified_counterexample(r) for r in cert.refutation
                                           if r.speed == known and r.verified), None)
    bounds = replace(cert.bounds.given, a_max=ref.values, a_margin=None)
    other = certify_crossing(robot, task, bounds, v_low=start, v_high=v_high, tol=tol, monte_carlo_runs=0,
                             refute=refute, refute_speeds=scan, executor=executor, seed=seed,
                             progress=suffixed(progress, " at the robot's a_max"),
                             kin=kin, imodel=imodel, bounce=False, v_guess=speed_guess(cert.v_min, used, ref),
                             refute_warm=warm, refute_tol=tol if refute_tol is None else refute_tol)
    bound, search = other.refutation_bound, other.refutation_search
    if known is not None and (bound is None or bound < known):
        # a verified counterexample under the default's bounds satisfies the robot's wider ones
        bound, search = known, SearchCompleteness.FOUND
    return replace(cert, at_robot_a_max=AtRobotAMax(
        ComparisonOutcome.COMPUTED, ref, other.verdict, other.v_min, bound, start, other.v_min_at_lower_end,
        other.elapsed_s, search))
