"""The float checks of a robot definition: :func:`check_definition` (every check: ``crosscert.validate``).

A :class:`~robots.base.Robot` is data plus one CasADi loop closure; most
mistakes in writing one (a pose coordinate in degrees, a bound in mm, a mode
sign flipped, a loop closure the interval evaluator reads differently from
CasADi) give no error, only wrong answers.  :func:`check_definition` runs a fixed
list of checks on seeded random configurations and returns a
:class:`ValidationReport` with one :class:`CheckResult` per check.

The interval checks need :mod:`verifier`, which this bottom layer may not
import: :func:`verifier.validation.validate` (also ``crosscert.validate``)
passes them in, as may any caller (``interval_checks``).  Without them they
are reported ``NOT_RUN``, never passed, whatever else was imported: the
report depends on the arguments only.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Callable

import numpy as np

from .base import Robot
from .errors import CrosscertError, ModelError
from .kinematics import KinematicModel

__all__ = ["CheckOutcome", "CheckResult", "ValidationReport", "Sample", "check_definition", "INTERVAL_CHECK_NAMES"]

#: Relative agreement required between CasADi's Jacobians and central differences of f.
JACOBIAN_RTOL = 1e-5
#: Largest ratio between ``side_i / a_max_i`` (or ``side_i / xd0_i``) of two pose coordinates
#: (``side`` = the sides of x_bounds): a bound in the wrong unit (mm for m, deg for rad) is off by 57 to 1000.
UNIT_RATIO = 20.0
#: Names of the interval checks the verifier provides (reported NOT_RUN when absent).
INTERVAL_CHECK_NAMES = ("interval-evaluation", "interval-containment")


class CheckOutcome(StrEnum):
    """Outcome of one check."""

    PASSED = "passed"
    FAILED = "failed"
    NOT_RUN = "not-run"


@dataclass(frozen=True)
class CheckResult:
    """One check: its name, outcome and a message naming the problem (or what was checked)."""

    name: str
    outcome: CheckOutcome
    message: str


@dataclass(frozen=True, eq=False)
class Sample:
    """Seeded valid configurations a check runs on.

    Attributes
    ----------
    X, Q : ndarray, shape (N, n)
        Poses (SI) and joints (rad or m) with ``f(X, Q, xi) = 0``, inside
        ``x_bounds`` and the joint range, away from the Type 2 locus.
    xi : ndarray, shape (m,)
        The geometry they solve (a random corner of ``[xi]``).
    """

    X: np.ndarray
    Q: np.ndarray
    xi: np.ndarray


#: ``check(robot, kinematic_model, sample, rng) -> CheckResult``.
IntervalCheck = Callable[[Robot, KinematicModel, Sample, np.random.Generator], CheckResult]


@dataclass(frozen=True)
class ValidationReport:
    """Every check of one robot.

    Attributes
    ----------
    robot_name : str
    checks : tuple of CheckResult
    """

    robot_name: str
    checks: tuple[CheckResult, ...]

    @property
    def ok(self) -> bool:
        """True when every check ran and passed."""
        return all(c.outcome is CheckOutcome.PASSED for c in self.checks)

    @property
    def failures(self) -> tuple[CheckResult, ...]:
        """The checks that failed or did not run."""
        return tuple(c for c in self.checks if c.outcome is not CheckOutcome.PASSED)

    def raise_if_failed(self) -> None:
        """Raise :class:`ModelError` naming every failed (or not run) check."""
        if not self.ok:
            raise ModelError(f"robot {self.robot_name} fails validation: "
                             + "; ".join(f"{c.name} {c.outcome}: {c.message}" for c in self.failures))


def _result(name: str, problems: list[str], passed: str) -> CheckResult:
    if problems:
        return CheckResult(name, CheckOutcome.FAILED, "; ".join(problems))
    return CheckResult(name, CheckOutcome.PASSED, passed)


def _check_units(robot: Robot) -> CheckResult:
    """Bounds in one system of units: the pose coordinates' time scales agree, eps_q is tiny, t_s is short."""
    side = robot.x_hi_array - robot.x_lo_array
    problems = []
    # time to cross x_bounds at a_max (squared) and at xd0: a robot's axes differ by a few
    # times at most; a bound in mm, deg or per minute is off by 57 to 3600
    for field, values, t in (("a_max", robot.a_max_array, side / robot.a_max_array),
                             ("xd0", np.array(robot.xd0), side / np.array(robot.xd0))):
        i, j = int(np.argmax(t)), int(np.argmin(t))
        if t[i] > UNIT_RATIO * t[j]:
            problems.append(
                f"{field}[{i}] = {values[i]:g} and {field}[{j}] = {values[j]:g} give x_bounds side / {field} of "
                f"{t[i]:.3g} and {t[j]:.3g} (ratio {t[i] / t[j]:.0f} > {UNIT_RATIO:g}): inconsistent units in "
                f"{field} or x_bounds (state units per axis: m/s^2 or rad/s^2, m/s or rad/s)")
    t_acc = float(np.min(np.sqrt(side / robot.a_max_array)))
    if robot.t_s > 0.1 * t_acc:
        problems.append(f"t_s = {robot.t_s:g} s is not short against the {t_acc:.3g} s to cross x_bounds at a_max "
                        "(t_s in s?)")
    q_span = float(np.min(robot.q_hi_array - robot.q_lo_array))
    if robot.eps_q > 1e-2 * q_span:
        problems.append(f"eps_q = {robot.eps_q:g} is more than 1 % of the smallest joint range {q_span:g} "
                        "(eps_q in rad for revolute and m for prismatic joints?)")
    return _result("units", problems, "a_max, xd0, t_s, eps_q and x_bounds are in consistent units")


def _sample(robot: Robot, km: KinematicModel, rng: np.random.Generator, count: int) -> Sample | None:
    """Random valid configurations: random poses in x_bounds, IK from random joints, kept when regular."""
    xi = np.where(rng.integers(0, 2, robot.m) == 1, robot.xi_hi_array, robot.xi_lo_array)
    lo, hi = robot.x_lo_array, robot.x_hi_array
    tries = 40 * count
    X = lo + (hi - lo) * rng.random((tries, robot.n))
    Qg = robot.q_lo_array + (robot.q_hi_array - robot.q_lo_array) * rng.random((tries, robot.n))
    Q, ok = km.ik_batch(X, xi, Qg)
    ok &= np.all((Q >= robot.q_lo_array) & (Q <= robot.q_hi_array), axis=1)
    if ok.any():
        with np.errstate(invalid="ignore"):
            ok[ok] = np.abs(km.normalised_mode_batch(X[ok], Q[ok], xi)) > 1e-3
    idx = np.nonzero(ok)[0][:count]
    if idx.size < max(2, count // 4):
        return None
    return Sample(X[idx], Q[idx], xi)


def _check_jacobians(km: KinematicModel, s: Sample) -> CheckResult:
    """``J_x`` and ``J_q`` against central differences of ``f`` (CasADi's numeric evaluation)."""
    problems = []
    for name, jac, var in (("J_x", km.jac_x_batch, 0), ("J_q", km.jac_q_batch, 1)):
        J = jac(s.X, s.Q, s.xi)
        for k in range(len(s.X)):
            base = [s.X[k], s.Q[k]]
            fd = np.empty((km.n, km.n))
            for j in range(km.n):
                h = 1e-6 * max(1.0, abs(base[var][j]))
                args_p, args_m = [a.copy() for a in base], [a.copy() for a in base]
                args_p[var][j] += h
                args_m[var][j] -= h
                fd[:, j] = (km.f_batch(args_p[0], args_p[1], s.xi)[0] - km.f_batch(args_m[0], args_m[1], s.xi)[0]) / (2 * h)
            scale = max(np.abs(fd).max(), 1e-300)
            err = np.abs(J[k] - fd).max() / scale
            if not err <= JACOBIAN_RTOL:
                problems.append(f"{name} differs from the finite differences of f by {err:.2g} (relative) at "
                                f"x = {np.round(s.X[k], 6).tolist()}")
                break
    return _result("jacobians", problems, f"J_x and J_q match central differences of f at {len(s.X)} points")


def _check_round_trip(robot: Robot, km: KinematicModel, s: Sample, rng) -> CheckResult:
    """IK then FK (and FK then IK) from perturbed guesses return the configuration."""
    side = robot.x_hi_array - robot.x_lo_array
    span = robot.q_hi_array - robot.q_lo_array
    problems = []
    Xg = s.X + 1e-3 * side * rng.uniform(-1, 1, s.X.shape)
    X, ok = km.fk_batch(s.Q, s.xi, Xg)
    bad = ~ok | (np.abs(X - s.X) > 1e-9 * np.maximum(side, 1.0)).any(axis=1)
    if bad.any():
        k = int(np.nonzero(bad)[0][0])
        problems.append(f"FK from a guess near x = {np.round(s.X[k], 6).tolist()} returned "
                        f"{np.round(X[k], 9).tolist()} (converged: {bool(ok[k])})")
    Qg = s.Q + 1e-3 * span * rng.uniform(-1, 1, s.Q.shape)
    Q, ok = km.ik_batch(s.X, s.xi, Qg)
    bad = ~ok | (np.abs(Q - s.Q) > 1e-9 * np.maximum(span, 1.0)).any(axis=1)
    if bad.any():
        k = int(np.nonzero(bad)[0][0])
        problems.append(f"IK from a guess near q = {np.round(s.Q[k], 6).tolist()} returned "
                        f"{np.round(Q[k], 9).tolist()} (converged: {bool(ok[k])})")
    return _result("ik-fk-round-trip", problems, f"IK and FK round-trip at {len(s.X)} points")


def _check_mode(robot: Robot, km: KinematicModel, s: Sample) -> CheckResult:
    """The declared geometric mode convention against ``mode_sign * sign(det J_x)``."""
    if robot.mode_reference is None:
        return CheckResult("mode-convention", CheckOutcome.NOT_RUN,
                           "the robot declares no geometric mode convention (Robot.mode_reference)")
    geo = np.array([int(robot.mode_reference(s.X[k], s.Q[k], s.xi)) for k in range(len(s.X))])
    det = km.mode_batch(s.X, s.Q, s.xi)
    bad = np.nonzero(geo != det)[0]
    if bad.size == 0:
        return CheckResult("mode-convention", CheckOutcome.PASSED,
                           f"mode_reference equals mode_sign * sign(det J_x) at {len(s.X)} points")
    flipped = bool(np.all(geo == -det))
    k = int(bad[0])
    return CheckResult("mode-convention", CheckOutcome.FAILED,
                       f"mode_reference gives {geo[k]:+d} but mode_sign * sign(det J_x) gives {det[k]:+d} at "
                       f"x = {np.round(s.X[k], 6).tolist()} ({bad.size}/{len(s.X)} points"
                       + ("; every sign is flipped: mode_sign has the wrong sign)" if flipped else ")"))


def check_definition(robot: Robot, *, seed: int = 0, samples: int = 16,
                     interval_checks: dict[str, IntervalCheck] | None = None) -> ValidationReport:
    """Check a robot definition on seeded random configurations.

    Checks, in order: ``model`` (the loop closure builds a kinematic model),
    ``units`` (bounds in consistent units, named field on failure),
    ``sampling`` (valid configurations exist in ``x_bounds``), ``jacobians``
    (CasADi's ``J_x``, ``J_q`` against central differences of ``f``),
    ``ik-fk-round-trip``, ``mode-convention`` (``Robot.mode_reference`` against
    ``mode_sign * sign(det J_x)``), then the interval checks
    (:data:`INTERVAL_CHECK_NAMES`: interval evaluations of ``f``, ``J_x``,
    ``J_q`` agree with CasADi; contracted boxes contain sampled truths).

    Parameters
    ----------
    robot : Robot
    seed : int
        Seed of every random draw.
    samples : int
        Configurations checked.
    interval_checks : dict, optional
        ``name -> check``; each of :data:`INTERVAL_CHECK_NAMES` missing is
        reported ``NOT_RUN``.  :func:`verifier.validation.validate` passes
        the verifier's.

    Returns
    -------
    ValidationReport
    """
    if not isinstance(robot, Robot):
        raise ModelError(f"check_definition needs a Robot, got {type(robot).__name__}")
    rng = np.random.default_rng(seed)
    checks: list[CheckResult] = []
    later = ("units", "sampling", "jacobians", "ik-fk-round-trip", "mode-convention", *INTERVAL_CHECK_NAMES)
    try:
        km = KinematicModel(robot)
    except CrosscertError as exc:
        checks.append(CheckResult("model", CheckOutcome.FAILED, str(exc)))
        checks += [CheckResult(n, CheckOutcome.NOT_RUN, "no kinematic model") for n in later]
        return ValidationReport(robot.name, tuple(checks))
    checks.append(CheckResult("model", CheckOutcome.PASSED, f"n = {robot.n}, m = {robot.m}"))
    checks.append(_check_units(robot))
    s = _sample(robot, km, rng, samples)
    if s is None:
        checks.append(CheckResult("sampling", CheckOutcome.FAILED,
                                  "IK from random joints found too few regular configurations inside x_bounds and "
                                  "the joint range: check x_bounds, q_lo/q_hi and the loop closure"))
        checks += [CheckResult(n, CheckOutcome.NOT_RUN, "no valid configuration") for n in later[2:]]
        return ValidationReport(robot.name, tuple(checks))
    checks.append(CheckResult("sampling", CheckOutcome.PASSED, f"{len(s.X)} regular configurations"))
    checks.append(_check_jacobians(km, s))
    checks.append(_check_round_trip(robot, km, s, rng))
    checks.append(_check_mode(robot, km, s))
    chosen = dict(interval_checks or {})
    for name in INTERVAL_CHECK_NAMES:
        fn = chosen.pop(name, None)
        if fn is None:
            checks.append(CheckResult(name, CheckOutcome.NOT_RUN, "needs the interval checks: call "
                                      "crosscert.verifier.validate(robot) (or crosscert.validate) for every check"))
        else:
            checks.append(_run(name, fn, robot, km, s, rng))
    for name, fn in chosen.items():
        checks.append(_run(name, fn, robot, km, s, rng))
    return ValidationReport(robot.name, tuple(checks))


def _run(name, fn, robot, km, s, rng) -> CheckResult:
    try:
        return fn(robot, km, s, rng)
    except CrosscertError as exc:
        return CheckResult(name, CheckOutcome.FAILED, str(exc))

