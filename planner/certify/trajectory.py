"""Certify a planned trajectory given by the user (a file or arrays), before it runs.

A user's own generator (a collocation planner, toppra along a curved path, a
computed-torque trajectory generator) gives the joints ``q`` (and optionally
the poses ``x``) of a crossing sampled at a constant period.
:func:`plan_from_trajectory` checks it and completes it into a
:class:`~planner.task.PlannedTrajectory`; :func:`certify_trajectory`
certifies it as :func:`~planner.certify.crossing.certify_crossing` certifies
its own plans, on the same certificate: the execution class, the forward run
and the window passes (:func:`~planner.certify.plan.certify_planned`), the
Monte Carlo confirmation when it certifies, and the counterexample search on
its readings when it does not.  :func:`certify_path` keeps the plan's path
and re-times it: the slowest speed at the singularity at which that path
certifies, and the refutation bound on the same path.

What the certificate covers is the executions of *this* plan
(:mod:`planner.certify.plan`, "What a certificate guarantees"): ``cartesian``
when the file gives the poses (the executions follow that path, any
geometry in the calibration box), ``joint`` when it gives the joints only
(the true joints within ``eps_q + tracking_error`` of the planned ones).
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from crosscert.robots import KinematicModel
from crosscert.robots.errors import InputError, SimulationError
from crosscert.verifier.model import IntervalModel
from crosscert.verifier.settings import Verdict
from crosscert.verifier.trajectory import Trajectory
from crosscert.verifier.trajfile import read_trajectory

from .. import refute
from ..locus import sign_changes
from ..montecarlo import monte_carlo_confirmation
from ..progress import Phase, enter
from ..simulate import random_geometry
from ..task import ExecutionKind, PlannedTrajectory, PlanningBounds, ResolvedBounds, resolved
from ..path import path_task_of
from ..refute.orchestrate import REFUTE_CAP_VARIABLES, REFUTE_CPU_TIME, refute_overrides
from .certificate import CrossingCertificate, package_versions
from .crossing import certify_crossing
from .plan import certify_planned

__all__ = ["PlanSource", "read_plan", "plan_from_trajectory", "certify_trajectory", "certify_path", "POSE_RESIDUAL_TOL"]

#: Largest ``|f(x, q, xi_plan)|`` accepted between a file's poses and joints, in the loop closure's units
#: (m^2 for the five-bar's squared lengths): a pose written with 6 significant digits passes, a column
#: of another robot or another plan does not.
POSE_RESIDUAL_TOL = 1e-6


@dataclass(frozen=True)
class PlanSource:
    """Where a given plan comes from: ``file`` (its name as given, or ``"<arrays>"``), its ``sha256`` (of the
    file's bytes; of the arrays' float64 bytes otherwise), its ``samples`` and period ``t_s`` (s), and whether
    its poses were ``given`` or computed by forward kinematics."""

    file: str
    sha256: str
    samples: int
    t_s: float
    poses: str

    def summary(self) -> dict:
        return {"file": self.file, "sha256": self.sha256, "samples": self.samples, "t_s": self.t_s,
                "poses": self.poses}


def read_plan(path, robot) -> tuple[Trajectory, str]:
    """The plan file ``path`` (``t, q1..qn`` and optionally ``x1..xn``; docs/file-formats.md) and its sha256.

    Raises
    ------
    TrajectoryFileError
        Unreadable file, bad columns or an uneven time column (the message names the line).
    """
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return read_trajectory(path, robot.n, nominal_t_s=robot.t_s), digest


def _arrays_digest(t, q, x) -> str:
    h = hashlib.sha256()
    for a in (t, q, x):
        if a is not None:
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()


def plan_from_trajectory(kin, traj: Trajectory, *, initial_mode: int | None = None, xd0=None,
                         name: str = "<arrays>", digest: str | None = None) -> tuple[PlannedTrajectory, PlanSource]:
    """Check a given plan and complete it: poses (given, else forward kinematics), rates, its crossing.

    Parameters
    ----------
    kin : robots.KinematicModel
    traj : verifier.Trajectory
        ``t`` (K,) s at a constant step, ``q`` (K, n), optional ``x`` (K, n), SI.
    initial_mode : int, optional
        +1 or -1: the assembly mode at the first sample.  Needed when the poses are not given (the joints
        alone do not say which mode the robot starts in); checked against them when they are.
    xd0 : array (n,), optional
        The stated initial speed bound, per pose axis (its unit per s): the plan's first step may move that
        fast; default the robot's ``xd0`` (a start at rest).
    name, digest
        The plan's source for the certificate (file name and sha256; the arrays' digest by default).

    Raises
    ------
    InputError
        A joint or pose outside the robot's range (the sample is named), poses that do not close the
        loop with the joints, a plan that does not start at rest (nor within ``xd0``), one that never
        crosses a Type 2 singularity (``det J_x`` keeps its sign) or crosses more than once.
    """
    robot = kin.robot
    xi = robot.xi_center
    t, q = np.asarray(traj.t, float), np.asarray(traj.q, float)
    K, n = q.shape
    if K < 3:
        raise InputError(f"{name}: a plan needs at least 3 samples, got {K}")
    t_s = float(traj.t_s)
    _in_range(name, q, robot.q_lo_array, robot.q_hi_array, "joint", robot.joint_units)
    x, poses = _plan_poses(kin, traj, t, q, xi, initial_mode, name)
    _in_range(name, x, robot.x_lo_array, robot.x_hi_array, "pose", robot.pose_units)
    xd = np.gradient(x, t_s, axis=0)
    xdd = np.gradient(xd, t_s, axis=0)
    qd = np.gradient(q, t_s, axis=0)
    qdd = np.gradient(qd, t_s, axis=0)
    _check_start(robot, x, t_s, xd0, name)
    k_sing, point = _crossing_sample(kin, x, q, xi, initial_mode, name)
    v = _velocity_at(x, k_sing, t_s)
    lengths = [i for i, u in enumerate(robot.pose_units) if u.value == "m"] or list(range(n))
    v_sing = float(np.linalg.norm(v[lengths]))
    for a in (t, q, x, xd, xdd, qd, qdd):
        a.setflags(write=False)
    plan = PlannedTrajectory(t=t, q=q, qd=qd, qdd=qdd, x=x, xd=xd, xdd=xdd, t_s=t_s, k_sing=k_sing, v_sing=v_sing,
                             crossing_point=point, xi_plan=xi)
    source = PlanSource(name, digest if digest is not None else _arrays_digest(t, q, traj.x), K, t_s, poses)
    return plan, source


def _plan_poses(kin, traj: Trajectory, t, q, xi, initial_mode: int | None, name: str) -> tuple[np.ndarray, str]:
    """The plan's poses and how they were obtained: the given ones, checked to close the loop with the joints
    ``q`` (K, n) at ``xi``, else forward kinematics by continuation from ``initial_mode``.

    Returns
    -------
    x : ndarray, shape (K, n)
        The poses, SI.
    poses : str
        ``"given"`` or ``"forward kinematics"``.

    Raises
    ------
    InputError
        Poses that do not close the loop (the first such sample is named), or joints only without an
        initial mode.
    """
    robot = kin.robot
    if traj.x is not None:
        x = np.asarray(traj.x, float)
        residual = np.max(np.abs(kin.f_batch(x, q, xi)), axis=1)
        bad = np.flatnonzero(~(residual <= POSE_RESIDUAL_TOL))
        if bad.size:
            k = int(bad[0])
            raise InputError(f"{name}: sample {k} (t = {t[k]:g} s): the poses x do not close the loop with the joints "
                             f"q of robot {robot.name} (|f| = {residual[k]:.3g} > {POSE_RESIDUAL_TOL:g}): a file of "
                             "another robot, or poses of another plan")
        return x, "given"
    if initial_mode not in (1, -1):
        raise InputError(f"{name}: the plan gives joints only: state its initial assembly mode (+1 or -1; "
                         "CLI --initial-mode), or give the poses as columns x1..xn")
    return _poses_by_continuation(kin, q, xi, initial_mode, name), "forward kinematics"


def _check_start(robot, x, t_s: float, xd0, name: str) -> None:
    """InputError when the plan's first step moves a pose axis faster than the initial speed bound.

    Parameters
    ----------
    x : ndarray, shape (K, n)
        The poses, SI.
    t_s : float
        Sampling period, s.
    xd0 : array (n,) or None
        The stated initial speed bound per pose axis (its unit per s); None: the robot's ``xd0``.
    """
    first = (x[1] - x[0]) / t_s
    start = np.asarray(robot.xd0 if xd0 is None else xd0, float)
    fast = np.flatnonzero(np.abs(first) > start)
    if fast.size:
        i = int(fast[0])
        unit = robot.velocity_units[i]
        raise InputError(f"{name}: the plan does not start at rest: its first step moves pose axis {i + 1} at "
                         f"{abs(first[i]):.4g} {unit}, above the initial speed bound {start[i]:g} {unit}; start at rest "
                         "or state the initial speed (PlanningBounds.xd0, CLI --xd0)")


def _crossing_sample(kin, x, q, xi, initial_mode: int | None, name: str) -> tuple[int, np.ndarray]:
    """The plan's one crossing of the Type 2 locus: the sample ``k_sing`` nearest it and the crossing point.

    A sample on the locus (up to rounding) when there is one, else the zero of the normalised mode between
    the last sample before and the first after, rounded to the nearer sample; the point is that sample's pose,
    or the linear interpolation at the zero (SI).

    Raises
    ------
    InputError
        A plan starting on the locus, one whose first mode contradicts ``initial_mode``, one that never
        crosses or crosses more than once.
    """
    nm = kin.normalised_mode_batch(x, q, xi)
    modes = kin.mode_batch(x, q, xi)
    m0 = int(modes[0])
    if m0 == 0:
        raise InputError(f"{name}: the plan starts on the Type 2 locus: start it off the locus")
    if initial_mode is not None and initial_mode != m0:
        raise InputError(f"{name}: --initial-mode {initial_mode:+d} contradicts the given poses, which start in "
                         f"mode {m0:+d}")
    ka_all, kb_all = sign_changes(modes.astype(float))  # a sample on the locus (mode 0) is bracketed once
    flips = kb_all
    if flips.size == 0:
        raise InputError(f"{name}: the plan never crosses a Type 2 singularity (det J_x keeps its sign, mode "
                         f"{m0:+d} from the first sample to the last): there is no assembly-mode change to certify")
    if flips.size > 1:
        raise InputError(f"{name}: the plan crosses the Type 2 locus {flips.size} times (samples "
                         f"{', '.join(str(int(k)) for k in flips[:5])}): certify one crossing per plan")
    ka, kb = int(ka_all[0]), int(kb_all[0])
    # the crossing instant: a sample on the locus (up to rounding) when there is one, else the zero of the
    # normalised mode between the last sample before and the first after, rounded to the nearer sample
    w = nm[ka] / (nm[ka] - nm[kb])
    if kb - ka > 1:
        k_sing = (ka + kb) // 2
        point = x[k_sing].copy()
    else:
        k_sing = ka if w <= 0.5 else kb
        point = x[ka] + w * (x[kb] - x[ka])
    return k_sing, point


def _velocity_at(x, k: int, t_s: float) -> np.ndarray:
    """The velocity at sample ``k``: the mean of the two one-sided second-order differences, exact when the
    acceleration is constant on each side (a time-optimal law switches it at the crossing), else central."""
    if 2 <= k <= len(x) - 3:
        left = (3.0 * x[k] - 4.0 * x[k - 1] + x[k - 2]) / (2.0 * t_s)
        right = (-3.0 * x[k] + 4.0 * x[k + 1] - x[k + 2]) / (2.0 * t_s)
        return 0.5 * (left + right)
    return np.gradient(x, t_s, axis=0)[k]


def _in_range(name, a, lo, hi, what, units) -> None:
    """InputError naming the first sample of ``a`` (K, n) outside ``[lo, hi]`` per column."""
    out = (a < lo) | (a > hi) | ~np.isfinite(a)
    if out.any():
        k, i = (int(v) for v in np.argwhere(out)[0])
        unit = units[i].value if hasattr(units[i], "value") else str(units[i])
        raise InputError(f"{name}: sample {k} leaves the robot's {what} range: {what} {i + 1} = {a[k, i]:.6g} {unit} "
                         f"outside [{lo[i]:.6g}, {hi[i]:.6g}] {unit}")


def _poses_by_continuation(kin, q, xi, mode: int, name: str) -> np.ndarray:
    """The poses of the joints ``q`` (K, n): the first in ``mode``, each next one the forward-kinematics
    solution nearest the linear extrapolation of the two before (the plan's smooth path, through the locus)."""
    robot = kin.robot
    sols = kin.fk_all(q[0], xi)
    ms = [kin.mode(s, q[0], xi) for s in sols]
    first = [s for s, m in zip(sols, ms) if m == mode]
    if not first:
        raise InputError(f"{name}: no forward-kinematics solution of the first sample lies in mode {mode:+d}")
    x = np.empty_like(q)
    x[0] = first[0]
    for k in range(1, len(q)):
        guess = x[k - 1] if k == 1 else 2.0 * x[k - 1] - x[k - 2]
        try:
            x[k] = kin.fk(q[k], xi, guess)
            if np.max(np.abs(x[k] - guess)) <= np.max(np.abs(x[k - 1] - guess)) + 1e-12:
                continue
        except SimulationError:
            pass
        # near the locus Newton may fail or land on the other branch: every solution, the nearest kept
        sols = kin.fk_all(q[k], xi)
        if not len(sols):
            raise InputError(f"{name}: sample {k}: no forward-kinematics solution at q = {q[k].tolist()} "
                             f"(the joints leave robot {robot.name}'s workspace); give the poses x1..xn")
        x[k] = sols[int(np.argmin(np.max(np.abs(sols - guess), axis=1)))]
    return x


def certify_trajectory(robot, plan, bounds: PlanningBounds | None = None, *, initial_mode: int | None = None,
                       execution=None, monte_carlo_runs: int = 50, refute_plan: bool = True, seed: int = 0,
                       progress=None, kin=None, imodel=None, source: PlanSource | None = None,
                       parallel: bool = True) -> CrossingCertificate:
    """Certify a given plan before it runs: the verdict for the plan as given, on the certificate schema.

    Parameters
    ----------
    robot : robots.Robot
    plan : path-like, verifier.Trajectory or PlannedTrajectory
        A plan file (``t, q1..qn[, x1..xn]``, docs/file-formats.md, "Planned trajectory"), a trajectory
        (``t``, ``q``, optional ``x``), or a completed plan.
    bounds : PlanningBounds, optional
        Its ``t_s`` is replaced by the plan's step; ``xd0`` states the plan's initial speed.  Resolved for
        ``robot`` here (:meth:`PlanningBounds.resolve`); the certificate keeps the resolved bounds.
    initial_mode : int, optional
        The mode at the first sample (needed when only joints are given).
    execution : ExecutionKind or str, optional
        The class of executions covered; default ``cartesian`` when the poses are given, ``joint`` when not.
    monte_carlo_runs : int
        Simulated executions when the plan is certified (0: none).
    refute_plan : bool
        When the plan is not certified, search a verified counterexample on its readings: found, no sound
        method can certify this plan (``refutation_bound`` is then its speed at the singularity).

    Returns
    -------
    CrossingCertificate
        ``verdict`` the plan's; ``v_min`` its speed at the singularity when certified, else None;
        ``plan_source`` the file and its sha256; ``task`` None.
    """
    t0 = time.perf_counter()
    kin = KinematicModel(robot) if kin is None else kin
    imodel = IntervalModel(robot) if imodel is None else imodel
    start = resolved(bounds, robot)  # its xd0: the bound the plan's first step is held against
    plan, src, given_x = _complete_plan(kin, robot, plan, start.assumptions.xd0, initial_mode)
    source = source or src
    kind = (ExecutionKind.CARTESIAN if given_x else ExecutionKind.JOINT) if execution is None else execution
    # the bounds of the certification: the plan's own step replaces any given t_s
    b = replace(start.given, t_s=float(plan.t_s), execution=kind).resolve(robot)
    if b.execution is ExecutionKind.CARTESIAN and not given_x:
        raise InputError("a plan of joints only has no path for 'cartesian' executions to follow: give its poses "
                         "(columns x1..xn) or certify 'joint' executions")
    m0 = int(kin.mode(plan.x[0], plan.q[0], plan.xi_plan))
    clock = {"setup": time.perf_counter() - t0}
    t1 = time.perf_counter()
    enter(progress, Phase.SEARCH, 1, unit="plan")
    run = certify_planned(kin, imodel, plan, b, parallel=parallel)
    if progress is not None:
        progress(1)
    clock["certificate"] = time.perf_counter() - t1
    certified = run.verdict is Verdict.MODE_CHANGED
    mc, rows, t1 = None, None, time.perf_counter()
    if certified and monte_carlo_runs:
        enter(progress, Phase.MONTE_CARLO, len(plan.q), unit="sample")
        mc = monte_carlo_confirmation(kin, imodel, plan, b, runs=monte_carlo_runs, seed=seed, progress=progress,
                                      execution=run.execution, parallel=parallel, envelope=run.envelope(robot, b.eps_q))
    clock["monte_carlo"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    if refute_plan and not certified and run.verdict is not Verdict.INCONSISTENT:
        rows = _refute_plan(kin, robot, plan, b, m0, seed, progress)
    clock["refutation"] = time.perf_counter() - t1
    return _trajectory_certificate(robot, plan, b, run, certified, mc, rows, clock, source, t0)


def _complete_plan(kin, robot, plan, xd0, initial_mode: int | None):
    """The plan given to :func:`certify_trajectory` completed: ``(plan, source, given_x)``; its first step
    within the initial speed bound ``xd0`` (per pose axis, its unit per s).

    ``plan`` a :class:`PlannedTrajectory`, ``source`` its :class:`PlanSource` (file and sha256, or the
    arrays' digest), ``given_x`` whether its poses were given (not computed by forward kinematics).
    """
    if isinstance(plan, (str, Path)):
        traj, digest = read_plan(plan, robot)
        given_x = traj.x is not None
        plan, src = plan_from_trajectory(kin, traj, initial_mode=initial_mode, xd0=xd0, name=str(plan),
                                         digest=digest)
    elif isinstance(plan, PlannedTrajectory):
        given_x = True
        src = PlanSource("<arrays>", _arrays_digest(plan.t, plan.q, plan.x), len(plan.t), float(plan.t_s), "given")
    else:
        given_x = plan.x is not None
        plan, src = plan_from_trajectory(kin, plan, initial_mode=initial_mode, xd0=xd0)
    return plan, src, given_x


def _refute_plan(kin, robot, plan: PlannedTrajectory, b: ResolvedBounds, m0: int, seed: int, progress):
    """The counterexample search on the readings of a plan that is not certified: the refutation's rows.

    Started at the centre of ``[xi]`` and at one seeded random geometry (corners included), at the plan's own
    speed at the singularity and the acceleration it derives.
    """
    enter(progress, Phase.REFUTATION, unit="")
    starts = [robot.xi_center, random_geometry(robot, np.random.default_rng(seed), corners=True)]
    found = refute.refutation_bound(kin, lambda _v: (plan.q, b.t_s), [plan.v_sing], m0=m0, xi_starts=starts,
                                    bounds=refute_overrides(b.for_plan(plan)),
                                    max_cpu_time=REFUTE_CPU_TIME, cap_variables=REFUTE_CAP_VARIABLES)
    return found.rows


def _trajectory_certificate(robot, plan: PlannedTrajectory, b: ResolvedBounds, run, certified: bool, mc, rows,
                            clock: dict, source: PlanSource, t0: float) -> CrossingCertificate:
    """The certificate of a given plan from its run (:func:`~planner.certify.plan.certify_planned`), Monte
    Carlo confirmation ``mc``, refutation ``rows`` (None: not run) and phase times ``clock`` (s); ``t0`` the
    start of :func:`certify_trajectory` (``time.perf_counter``, s)."""
    return CrossingCertificate(
        verdict=run.verdict,
        v_min=plan.v_sing if certified else None,
        refutation_bound=plan.v_sing if rows and rows[0].verified else None,
        trials=(run.trial(),),
        trajectory=plan,
        enclosures=run.forward,
        bounds=b,
        a_max_used=run.acceleration,
        monte_carlo=mc,
        versions=package_versions(),
        elapsed_s=time.perf_counter() - t0,
        refutation=tuple(rows or ()),
        execution=run.execution,
        timings_s=clock,
        robot_name=robot.name,
        param_names=tuple(robot.param_names),
        window=run.window,
        acceleration_units=robot.acceleration_units,
        joint_units=robot.joint_units,
        pose_units=robot.pose_units,
        refutation_ran=rows is not None,
        plan_source=source,
    )


def certify_path(robot, plan: PlannedTrajectory, bounds: PlanningBounds | None = None, *, source: str = "<path>",
                 kin=None, imodel=None, **kwargs) -> CrossingCertificate:
    """The minimal time scaling of a given plan's path that certifies: its path kept, re-timed.

    The plan's poses become a :class:`~planner.path.PathTask` (a curve through the locus, its knots the plan's
    samples) and :func:`~planner.certify.crossing.certify_crossing` searches the slowest speed at the
    singularity whose smoothstep timing of that path certifies, with the refutation bound on the same path.
    ``bounds`` as for :func:`certify_trajectory` (the plan's sampling period; a given plan's certificate's
    bounds, its execution class with them, are taken as they were given); ``kwargs`` go to
    ``certify_crossing`` (``v_low``, ``tol``, ``monte_carlo_runs``, ``refute``, ``executor``, ...).
    """
    kin = KinematicModel(robot) if kin is None else kin
    given = bounds.given if isinstance(bounds, ResolvedBounds) else bounds or PlanningBounds()
    b = replace(given, t_s=float(plan.t_s))  # resolved once, by certify_crossing
    task = path_task_of(kin, plan, source)
    return certify_crossing(robot, task, b, kin=kin, imodel=imodel, **kwargs)
