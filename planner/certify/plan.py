"""Planning-time certification of a Type 2 singularity crossing.

Before a crossing is executed, answer: how fast must the robot cross for the
assembly-mode change to be certified from its encoders, and prove it.

* :func:`certify_plan` — the tracker run on inputs that cover every admissible
  execution of a plan (see *What a certificate guarantees* below);
* :func:`minimal_v_sing` — bisection search of the smallest certified speed;

Plans come from :mod:`planner.plan`, the Monte Carlo confirmation from
:mod:`planner.montecarlo`, the whole certification of a task from :mod:`planner.certify.crossing`.

What a certificate guarantees
-----------------------------
Let ``q_plan(t_k)`` be the planned joints (computed with the planning
geometry, the centre of ``[xi]``).  An *admissible execution* is any motion
with (i) one constant true geometry, (ii) ``|xdd_i(t)| <= a_max_i`` at all
times, (iii) joints in the execution class of :mod:`planner.execution` —
``cartesian`` (default): the lengths in ``[xi]`` and effective angles
``q(t_k) + delta = q_plan(t_k) + c + w_k`` with one constant ``c`` in the
derived box ``C``, ``|w_k| <=`` the class's reading error and ``w`` changing
by at most the class's drift per sample (this holds for
every execution that follows the planned path, whatever its geometry in
``[xi]``: the encoders absorb the offsets); ``joint``: true joints within
``eps_q + tracking_error`` of ``q_plan(t_k)``, geometry in ``[xi]`` —, (iv) a
start at rest up to the robot's ``xd0`` and in the plan's initial assembly
mode, with the pose inside the robot's ``x_bounds``, (v) samples exactly
``t_s`` apart.  The certifying run feeds the tracker the readings
``q_plan(t_k)`` with the class's reading error and geometry box: by the
tracker's soundness (docs/soundness.md) its boxes contain the pose and
velocity of every admissible execution, so when it reports ``mode-changed``
every admissible execution ends in the other assembly mode.  With ``window``
reasoning (``PlanningBounds.reasoning``, the default) a speed the tracker
leaves undecided is decided by window passes on the same inputs
(:func:`verifier.window.track_window`): they refute "the run ends in the
initial mode" only if no motion satisfying the same assumptions does, so
the guarantee is the same.

The midpoint-preconditioned Newton step and the fixpoint thresholds are not
inclusion-monotone: re-running the tracker on one execution's (narrower)
readings is not guaranteed to certify whenever the planning run did.  The
certificate therefore never relies on such a re-run: it is a statement about
every admissible execution, proved by the planning run itself.  Whether the
run-time tracker (robot's own ``[xi]``, readings within ``eps_q``) detects
the change on each execution is what the Monte Carlo confirmation measures,
on executions checked to be admissible.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from crosscert.robots import KinematicModel
from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import TrackerSettings, Verdict
from crosscert.verifier.tracker import TrackResult, track
from crosscert.verifier.window import Explainer, Reasoning, WindowResult, track_window

from .. import execution as ex_
from ..acceleration import AccelerationAssumption
from ..execution_proof import execution_class
from ..plan import plan_crossing
from ..refute import RefutingExplainer
from ..task import PlannedTrajectory, PlanningBounds, ResolvedBounds, resolved
from .envelope import CertifiedEnvelope

__all__ = [
    "SpeedTrial",
    "certify_plan",
    "certify_plan_window",
    "CERTIFY_WINDOW_GEOMETRIES",
    "tracker_settings",
    "minimal_v_sing",
    "search_v_min",
    "certify_speed",
    "certify_planned",
    "CertifiedRun",
    "SpeedSearch",
]


@dataclass(frozen=True)
class SpeedTrial:
    """One tried speed: the paper's Table II columns (widths of the forward tracker's boxes),
    the verdict and the forward tracker's own verdict (they differ where window passes decided)."""

    v_sing: float
    verdict: Verdict
    max_width_pose: float  # m
    max_width_velocity: float  # m/s
    certified_at_step: int | None  # first sample of the forward tracker's certified streak; None: not certified
    forward_verdict: Verdict


#: Geometry sub-boxes per final-mode hypothesis in the window passes of a certification
#: (the robot's partition halved up to this count; docs/tracker.md, "Window reasoning").
CERTIFY_WINDOW_GEOMETRIES = 16


# ------------------------------------------------------------------ planning
def tracker_settings(b: ResolvedBounds, cls: ex_.ExecutionClass) -> TrackerSettings:
    """Tracker settings of a certifying run: the bounds for one plan (``b``, :meth:`ResolvedBounds.for_plan`:
    ``t_s``, ``a_max``, ``xd0``) with the class's reading error, drift and geometry box, and the bounds'
    geometry hypotheses."""
    return TrackerSettings(assumptions=cls.assumptions(b.assumptions), xi_splits=b.xi_splits)


def certify_plan(imodel: IntervalModel, plan: PlannedTrajectory, bounds: PlanningBounds | ResolvedBounds,
                 initial_mode: int, *,
                 execution: ex_.ExecutionClass | None = None, kin=None, progress=None) -> TrackResult:
    """Run the tracker on inputs covering every admissible execution of ``plan``.

    Readings ``q_plan`` with the class's reading error and geometry box
    (``execution``, derived with :func:`execution_class` when not given; ``kin``
    is then the robot's ``KinematicModel``, built when absent); the initial box
    encloses every start pose of mode ``initial_mode`` for every geometry of
    the box.  ``MODE_CHANGED`` certifies every admissible execution.  The
    forward tracker's run; :func:`certify_plan_window` adds the window passes.
    ``progress(k)`` (optional) after each tracked sample.  ``bounds``: resolved for the robot (for this
    plan or not: :meth:`ResolvedBounds.for_plan`), or resolved here (:func:`planner.task.resolved`).
    """
    robot = imodel.robot
    b = resolved(bounds, robot).for_plan(plan)
    if execution is None:
        execution = execution_class(kin if kin is not None else KinematicModel(robot), plan, b)
    s = tracker_settings(b, execution)
    return track(imodel, plan.q, s, initial_mode=initial_mode, xi_box=execution.xi_box, progress=progress)


def certify_plan_window(imodel: IntervalModel, plan: PlannedTrajectory, bounds: PlanningBounds | ResolvedBounds,
                        initial_mode: int, *, execution: ex_.ExecutionClass | None = None, kin=None,
                        max_geometries: int = CERTIFY_WINDOW_GEOMETRIES, parallel: bool = True,
                        explainer: Explainer | None = None) -> WindowResult:
    """:func:`certify_plan` with window passes (:func:`verifier.window.track_window`) on the same inputs.

    ``bounds`` as for :func:`certify_plan` (``a_max`` the plan's: :meth:`ResolvedBounds.for_plan`).  ``MODE_CHANGED``
    certifies every admissible execution, as for :func:`certify_plan`.  ``parallel``: the geometry
    sub-boxes over the thread slots (the same boxes either way).  The window's one-motion refutation
    runs over ``bounds.one_motion`` samples (0: not tried).  ``explainer`` (e.g.
    :class:`planner.refute.RefutingExplainer`): a verified bounce of the plan's readings stops the window
    early with ``unknown`` (no sound method can certify ``MODE_CHANGED`` then); ``None``: not asked.
    """
    robot = imodel.robot
    b = resolved(bounds, robot).for_plan(plan)
    if execution is None:
        execution = execution_class(kin if kin is not None else KinematicModel(robot), plan, b)
    s = tracker_settings(b, execution)
    return track_window(imodel, plan.q, s, initial_mode=initial_mode, xi_box=execution.xi_box,
                        max_geometries=max_geometries, parallel=parallel, goal=Verdict.MODE_CHANGED,
                        one_motion=b.one_motion, explainer=explainer)


@dataclass(frozen=True, eq=False)
class CertifiedRun:
    """One speed certified as :func:`certify_speed` runs it (a question of the speed search).

    Attributes
    ----------
    plan : PlannedTrajectory
    execution : ExecutionClass
        The admissible executions of this plan alone.
    acceleration : AccelerationAssumption
        The acceleration bound assumed, per pose axis, with its unit and source.
    forward : TrackResult
        The forward tracker's run (:func:`certify_plan`).
    window : WindowResult or None
        The window passes on the same inputs (:func:`certify_plan_window`),
        run when the forward run left the verdict ``unknown`` under ``window``
        reasoning; ``None`` otherwise.
    """

    plan: PlannedTrajectory
    execution: ex_.ExecutionClass
    acceleration: AccelerationAssumption
    forward: TrackResult
    window: WindowResult | None

    @property
    def verdict(self) -> Verdict:
        """The run's verdict: the window passes' when they ran, else the forward run's."""
        return (self.window or self.forward).verdict

    def envelope(self, robot, eps_q) -> CertifiedEnvelope:
        """What ``monitor --certificate`` holds a run of this plan against (a decided run only), readings
        within ``eps_q`` (joint units)."""
        at, _by = decision_sample(self.forward, self.verdict, len(self.plan.q))
        final = -self.forward.initial_mode if self.verdict is Verdict.MODE_CHANGED else self.forward.initial_mode
        return CertifiedEnvelope.of(robot, self.plan.q, self.plan.t_s, self.execution.summary(), eps_q,
                                    verdict=self.verdict, decided_at=at, initial_mode=self.forward.initial_mode,
                                    final_mode=final)

    def trial(self) -> SpeedTrial:
        """The row of the search's table."""
        f = self.forward
        return SpeedTrial(float(self.plan.v_sing), self.verdict, float(f.max_width_pose), float(f.max_width_velocity),
                          None if f.certified_at_step < 0 else int(f.certified_at_step), f.verdict)


def decision_sample(forward: TrackResult, verdict: Verdict, samples: int) -> tuple[int, str]:
    """``(sample, by)``: where a certifying run of ``samples`` samples reached ``verdict``: the forward pass's
    streak start (``"forward"``) when it reached that verdict, else the last sample (``"window"``: the window
    passes read the whole run)."""
    if forward.verdict is verdict and forward.certified_at_step >= 0:
        return int(forward.certified_at_step), "forward"
    return samples - 1, "window"


def certify_speed(kin, imodel, task, bounds, v_sing, *, progress=None, parallel: bool = True) -> CertifiedRun:
    """Plan ``task`` at ``v_sing`` (m/s) and certify that plan alone (forward run, then window passes if undecided).

    What the certificate of ``v_sing`` is: its verdict ``MODE_CHANGED``
    certifies every admissible execution of the plan (module docstring).
    ``parallel``: window passes over the thread slots (the same boxes; off
    where another process holds the other cores).  ``bounds`` as for :func:`certify_plan`.
    """
    b = resolved(bounds, kin.robot)
    return certify_planned(kin, imodel, plan_crossing(kin, task, v_sing, b), b, progress=progress, parallel=parallel)


def certify_planned(kin, imodel, plan: PlannedTrajectory, bounds, *, progress=None,
                    parallel: bool = True) -> CertifiedRun:
    """Certify one plan alone: its execution class, the forward run, then window passes if undecided.

    The initial assembly mode is that of the plan's first pose and joints at the planning geometry.  Its
    verdict ``MODE_CHANGED`` certifies every admissible execution of the plan (module docstring).
    ``bounds`` as for :func:`certify_plan`.
    """
    b = resolved(bounds, kin.robot).for_plan(plan)
    cls = execution_class(kin, plan, b)
    m0 = int(kin.mode(plan.x[0], plan.q[0], plan.xi_plan))
    forward = certify_plan(imodel, plan, b, m0, execution=cls, progress=progress)
    window = None
    if forward.verdict is Verdict.UNKNOWN and b.reasoning is Reasoning.WINDOW:
        # a verified bounce stops the window early: that speed cannot be certified by any sound method
        window = certify_plan_window(imodel, plan, b, m0, execution=cls, parallel=parallel,
                                     explainer=RefutingExplainer())
    return CertifiedRun(plan, cls, b.acceleration, forward, window)


@dataclass(frozen=True, eq=False)
class SpeedSearch:
    """Result of :func:`search_v_min`.

    Attributes
    ----------
    v_min : float or None
        Slowest certified speed, m/s (``None``: ``v_high`` does not certify).
    trials : tuple of SpeedTrial
        Every tried speed, sorted.
    runs : dict
        ``{v_sing: CertifiedRun}`` of every tried speed (the run at ``v_min`` is its certificate).
    """

    v_min: float | None
    trials: tuple
    runs: dict = field(repr=False)


def search_v_min(kin, imodel, task, bounds, v_low, v_high, *, tol=0.01, progress=None, observe=None,
                 parallel: bool = True, v_guess=None) -> SpeedSearch:
    """Smallest certified ``v_sing`` in ``[v_low, v_high]`` to ``tol`` (m/s), by bisection.

    The fastest speed ``v_high`` is certified first; if it is not, there is
    no ``v_min``.  Otherwise the bracket ``(v_fail, v_cert)`` starts as
    ``(v_low, v_high)`` and each question, at its midpoint, moves one end:
    to the midpoint when it certifies (``v_cert``), else the other end
    (``v_fail``).  ``v_low`` is presumed not to certify until the bracket
    reaches it; it is then tried itself.  A question is one plan, certified
    alone (:func:`certify_speed`): about ``log2((v_high - v_low) / tol)``
    questions instead of a grid of speeds.

    Certification need not be monotone in the speed: the table of every
    trial is returned, and the result is the slowest certified speed such
    that every tried speed above it was certified (bisection keeps every
    failed speed below ``v_cert``).  When monotonicity fails, the result is
    still certified (its own run certified it); only a slower certified
    speed may have been missed.

    With ``v_guess`` (m/s, e.g. the ``v_min`` of a nearby task) the same
    bisection runs with the answers it has not asked predicted from the
    guess (certified at or above it) and from the answers asked so far; only
    the two ends of the bracket it ends on are asked, and the guess moves
    ``tol``, ``2 tol``, ``4 tol``... when one of them is answered against its
    prediction (:func:`_search_from_guess`).  A guess in the answer's cell of
    the bisection's grid takes 2 questions instead of about 9, one a few
    cells away 3-5.  The result keeps the same guarantee (certified by its
    own run, every tried speed above it certified, a failed one within
    ``tol`` below it unless it is ``v_low``), and lies on the bisection's
    grid: when certification is monotone it is the speed the search without
    a guess finds.

    ``observe(trial)`` (optional) is called with each :class:`SpeedTrial` as
    it completes (:func:`~planner.certify.crossing.certify_crossing` passes certified speeds to the counterexample
    searches running meanwhile); ``progress(k)`` after each tracked sample;
    ``parallel`` as for :func:`certify_speed`.
    """
    b = resolved(bounds, kin.robot)
    v_low, v_high = V.positive("v_low", v_low), V.positive("v_high", v_high)
    tol = V.positive("tol", tol)
    if not v_low < v_high:
        raise InputError(f"need v_low < v_high, got [{v_low}, {v_high}]")
    runs: dict[float, CertifiedRun] = {}

    def certified(v) -> bool:
        if v not in runs:
            runs[v] = certify_speed(kin, imodel, task, b, v, progress=progress, parallel=parallel)
            if observe is not None:
                observe(runs[v].trial())
        return runs[v].verdict is Verdict.MODE_CHANGED

    lowest, highest = round(float(v_low), 6), round(float(v_high), 6)
    if v_guess is None:
        _fail, v_min = _bisect(certified, lowest, highest, tol)
    else:
        v_min = _search_from_guess(certified, runs, V.positive("v_guess", v_guess), lowest, highest, tol)
    return SpeedSearch(v_min, tuple(runs[v].trial() for v in sorted(runs)), runs)


def _bisect(answer, lowest: float, highest: float, tol: float) -> tuple:
    """``(v_fail, v_cert)`` of the bisection of :func:`search_v_min` with answers ``answer(v)``; ``v_cert`` is
    None when ``highest`` does not certify.  ``v_fail`` is ``lowest`` (presumed) when no question failed."""
    v_cert, v_fail = highest, lowest
    if not answer(v_cert):
        return v_fail, None
    while v_cert - v_fail > tol:
        mid = round(0.5 * (v_fail + v_cert), 6)
        if mid in (v_fail, v_cert):  # tol below the rounding of speeds
            break
        if answer(mid):
            v_cert = mid
        else:
            v_fail = mid
    if v_fail == lowest and answer(v_fail):  # no question failed: v_low itself
        v_cert = v_fail
    return v_fail, v_cert


def _search_from_guess(certified, runs: dict, guess: float, lowest: float, highest: float, tol: float):
    """``v_min`` of :func:`search_v_min` from ``guess``: its bisection, asking only where the answer is open.

    Until a failed speed lies below a certified one, the bisection of ``[lowest, highest]`` runs on
    predicted answers (fail at or below the fastest asked failure, certify at or above the slowest asked
    certified speed, else certify from the guess on) and the two ends of the bracket it ends on are
    asked; the guess moves ``tol``, ``2 tol``, ``4 tol``... past an end answered against its prediction
    (on the way down, past each newly asked certified end, without asking the speed below it).
    Once a failure lies below a certified speed, the bisection runs again asking every speed between
    them, as the search without a guess would.  Asked speeds fail only at or below the fastest failure, so
    every asked speed above ``v_min`` certified; when certification is monotone the asked answers are
    those the search without a guess would get, so the result is its result.
    """
    g, step, down = min(max(guess, lowest), highest), tol, False
    while True:
        failed = max((u for u in runs if runs[u].verdict is not Verdict.MODE_CHANGED), default=-math.inf)
        ceiling = min((u for u in runs if u > failed), default=math.inf)  # every asked speed above failed certified
        if failed > -math.inf and ceiling < math.inf:  # bracketed: ask what lies between, as the bisection does
            v_fail, v_cert = _bisect(lambda v: v > failed and (v >= ceiling or certified(v)), lowest, highest, tol)
        else:
            v_fail, v_cert = _bisect(lambda v: v > failed and (v >= ceiling or v >= g), lowest, highest, tol)
        if v_cert is None:  # only when the fastest speed was asked and failed
            return None
        if v_cert not in runs:
            if not certified(v_cert):  # the answer lies above: move the guess up past it
                g, step = min(v_cert + step, highest), 2.0 * step
            elif down:  # still certified on the way down: on, without asking the speed below
                g, step = max(v_cert - step, lowest), 2.0 * step
        elif v_fail == v_cert or failed >= v_fail:
            return v_cert
        elif certified(v_fail):  # the answer lies below: move the guess down past it
            g, step, down = max(v_fail - step, lowest), 2.0 * step, True


def minimal_v_sing(kin, imodel, task, bounds, v_low, v_high, *, tol=0.01, progress=None, observe=None):
    """:func:`search_v_min`'s speed and table: ``(v_min or None, list of SpeedTrial sorted by speed)``."""
    r = search_v_min(kin, imodel, task, bounds, v_low, v_high, tol=tol, progress=progress, observe=observe)
    return r.v_min, list(r.trials)
