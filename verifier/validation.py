"""Every check of a robot definition: :func:`validate`, the robots layer's checks with the interval ones.

* ``interval-evaluation`` — the interval tapes of ``f``, ``J_x`` and ``J_q``
  on point boxes enclose CasADi's float values (up to a few ulps of CasADi's
  own rounding): the tapes read the loop closure as CasADi does;
* ``interval-containment`` — at sampled true configurations with the
  geometry at a corner of ``[xi]`` and readings off by up to ``eps_q``, the
  contractors of the tracker (HC4, interval Newton) keep the true pose in a
  box around it, and the enclosures of ``f``, ``J_x``, ``J_q`` and
  ``det J_x`` over that box contain their values at random points of it.
"""

from __future__ import annotations

import numpy as np

from crosscert.robots.validation import CheckOutcome, CheckResult, ValidationReport
from crosscert.robots.validation import check_definition

from .contractors import hc4_pose, newton
from .model import IntervalModel

__all__ = ["validate", "check_interval_evaluation", "check_interval_containment", "INTERVAL_CHECKS"]

#: Relative slack for CasADi's float rounding when comparing with an outward-rounded enclosure.
_FLOAT_RTOL = 1e-12


def _outside(lo, hi, v):
    slack = _FLOAT_RTOL * np.maximum(np.abs(v), 1e-300)
    return ~((lo - slack <= v) & (v <= hi + slack))


def check_interval_evaluation(robot, km, sample, rng) -> CheckResult:
    """Interval tapes on point boxes against CasADi's float values."""
    im = IntervalModel(robot)
    X, Q = sample.X, sample.Q
    XI = np.broadcast_to(sample.xi, (len(X), robot.m))
    problems = []
    for name, tape, ref in (("f", im.tape_f, km.f_batch(X, Q, sample.xi)),
                            ("J_x", im.tape_jx, km.jac_x_batch(X, Q, sample.xi)),
                            ("J_q", im.tape_jq, km.jac_q_batch(X, Q, sample.xi))):
        lo, hi = tape.evaluate([(X, X), (Q, Q), (XI, XI)])[0]
        lo, hi = lo.reshape(ref.shape), hi.reshape(ref.shape)
        bad = _outside(lo, hi, ref).reshape(len(X), -1).any(axis=1)
        if bad.any():
            k = int(np.nonzero(bad)[0][0])
            problems.append(f"the interval evaluation of {name} misses CasADi's value at x = "
                            f"{np.round(X[k], 6).tolist()}")
    if problems:
        return CheckResult("interval-evaluation", CheckOutcome.FAILED, "; ".join(problems))
    return CheckResult("interval-evaluation", CheckOutcome.PASSED,
                       f"interval f, J_x, J_q enclose CasADi's values at {len(X)} points")


def check_interval_containment(robot, km, sample, rng) -> CheckResult:
    """Contracted boxes and enclosures over boxes contain sampled truths."""
    im = IntervalModel(robot)
    X, Q = sample.X, sample.Q
    B, n = X.shape
    eps = robot.eps_q
    err = eps * rng.choice([-1.0, 1.0], size=Q.shape)  # readings at the edge of the error bound
    Qm = Q + err * (1 - 1e-9)
    Qb = (Qm - eps, Qm + eps)
    XIb = (np.broadcast_to(robot.xi_lo_array, (B, robot.m)).copy(), np.broadcast_to(robot.xi_hi_array, (B, robot.m)).copy())
    side = robot.x_hi_array - robot.x_lo_array
    half = 1e-3 * side * rng.uniform(0.5, 1.0, X.shape)
    Xb = (X - half * rng.uniform(0.2, 1.0, X.shape), X + half * rng.uniform(0.2, 1.0, X.shape))
    problems = []
    Xc = Xb
    for _ in range(4):
        Xc, Qc, _xi = hc4_pose(im, Xc, Qb, XIb)
        Xc = newton(im, Xc, Qc, XIb, "x")
    bad = np.nonzero(((X < Xc[0]) | (X > Xc[1])).any(axis=1))[0]
    if bad.size:
        k = int(bad[0])
        problems.append(f"contraction lost the true pose {np.round(X[k], 6).tolist()} (box {Xc[0][k].tolist()} .. "
                        f"{Xc[1][k].tolist()})")
    # enclosures over the boxes contain the values at random points inside them
    t = rng.random(X.shape)
    P = Xb[0] + t * (Xb[1] - Xb[0])
    Qp = Qb[0] + rng.random(Q.shape) * (Qb[1] - Qb[0])
    xp = robot.xi_lo_array + rng.random(robot.m) * (robot.xi_hi_array - robot.xi_lo_array)
    for name, tape, ref in (("f", im.tape_f, km.f_batch(P, Qp, xp)), ("J_x", im.tape_jx, km.jac_x_batch(P, Qp, xp)),
                            ("J_q", im.tape_jq, km.jac_q_batch(P, Qp, xp)),
                            ("det J_x", im.tape_det, robot.mode_sign * km.det_batch(P, Qp, xp))):
        lo, hi = tape.evaluate([Xb, Qb, XIb])[0]
        lo, hi = lo.reshape(ref.shape), hi.reshape(ref.shape)
        if _outside(lo, hi, ref).any():
            problems.append(f"the enclosure of {name} over a box misses its value at a point of the box")
    if problems:
        return CheckResult("interval-containment", CheckOutcome.FAILED, "; ".join(problems))
    return CheckResult("interval-containment", CheckOutcome.PASSED,
                       f"contracted boxes and enclosures of f, J_x, J_q, det J_x contain the truth at {B} points")


#: The interval checks, by name (:data:`robots.validation.INTERVAL_CHECK_NAMES`).
INTERVAL_CHECKS = {"interval-evaluation": check_interval_evaluation,
                   "interval-containment": check_interval_containment}


def validate(robot, *, seed: int = 0, samples: int = 16) -> ValidationReport:
    """Every check of ``robot``: :func:`robots.validation.check_definition` with :data:`INTERVAL_CHECKS`.

    Parameters
    ----------
    robot : Robot
    seed : int
        Seed of every random draw.
    samples : int
        Configurations checked.

    Returns
    -------
    ValidationReport
        ``.ok`` when every check ran and passed.
    """
    return check_definition(robot, seed=seed, samples=samples, interval_checks=INTERVAL_CHECKS)
