"""Execution classes: which motions a planning-time certificate covers.

A certificate is a tracker run on inputs that cover every reading an
*admissible execution* of a plan can produce (``planner.certify``).  This
module states the two classes of admissible executions and derives the
tracker inputs for each.

``joint``
    The true joints stay within ``eps_q + tracking_error`` of the planned
    joints ``q_plan(t_k)``; the geometry is anywhere in ``[xi]``.  This is the
    literal class of the paper's planning perspective, but a robot whose
    geometry differs from the planning geometry cannot follow ``q_plan``
    through the singularity: its joints must deviate by the geometry error
    (up to 7.7 mrad on the calibration box measured in docs/planning.md),
    which no small ``tracking_error`` covers.

``cartesian`` (default)
    The end-effector follows the planned path, the geometry is anywhere in
    ``[xi]``.  With additive joint offsets (``Robot.joint_offsets``: the loop
    closure reads joint ``i`` only through ``q_i + xi_j``), the physics depends
    on the *effective* angle ``q_i + xi_j``, so the class is stated on it:

        ``q_k + delta = q_plan(t_k) + c + w_k``, ``c`` in ``C``,
        ``|w_k| <= eps_q + tracking_error + e``,
        ``|w_k - w_{k-j}| <= 2 (eps_q + tracking_error) + j d``

    for one unknown constant ``c`` per execution (the part of the geometry
    error that the path does not change), a drift ``w_k`` bounded by ``e``
    (plus ``eps_q + tracking_error``) that changes by at most ``d`` per sample.
    The tracker covers it exactly by taking ``C`` as the box of the offset
    parameters, ``w`` as reading error (``f(x, q_plan + w, (lengths, c)) =
    0``) and the drift bound for differences of readings
    (``TrackerSettings.eps_q_fast`` and ``drift_rate = d / t_s``).  ``C``,
    ``e`` and ``d`` are proved over the whole box ``[xi]`` by
    :mod:`planner.execution_proof` (what a certificate uses); when that proof
    is not available they are measured by :func:`cartesian_class` on sampled
    geometries (``ExecutionClass.proved`` says which).  An execution is
    checked against them by :func:`in_class`.

Nothing here names a robot.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from crosscert.robots.assumptions import Assumptions
from crosscert.robots.errors import InputError, SimulationError
from crosscert.verifier import interval as I

__all__ = ["ExecutionKind", "ExecutionClass", "joint_class", "cartesian_class", "effective_deviation", "in_class"]


class ExecutionKind(StrEnum):
    """Class of admissible executions a certificate covers."""

    CARTESIAN = "cartesian"  #: the end-effector follows the planned path, any geometry in [xi]
    JOINT = "joint"  #: joints within eps_q + tracking_error of the planned joints


@dataclass(frozen=True, eq=False)
class ExecutionClass:
    """The admissible executions of a plan, as tracker inputs.

    Attributes
    ----------
    kind : ExecutionKind
    reading_error : float
        Half-width of the tracker's reading intervals around ``q_plan(t_k)``,
        rad: ``eps_q + tracking_error`` (+ the drift bound ``e`` for
        ``cartesian``).
    drift : float
        ``e``, rad (0 for ``joint``).
    fast_error : float
        ``eps_q + tracking_error``, rad: the part of the reading error not
        bound to drift slowly.
    drift_per_sample : float or None
        ``d``, rad per sample (``None`` for ``joint``: readings err
        independently).
    xi_lo, xi_hi : ndarray, shape (m,)
        Geometry box of the certifying run: ``[xi]`` with, for ``cartesian``,
        the offset parameters replaced by ``C``.
    derivation : dict
        How ``C`` and ``e`` were obtained (geometries tried, largest drift and
        constant part measured, safety factor).
    proved : bool
        Whether ``C``, ``e`` and ``d`` are proved for every geometry of
        ``[xi]`` (:mod:`planner.execution_proof`) rather than measured.
    proof : dict
        The proof's method and cost, or why it was not proved.
    """

    kind: ExecutionKind
    reading_error: float
    drift: float
    xi_lo: np.ndarray
    xi_hi: np.ndarray
    derivation: dict = field(default_factory=dict, compare=False)
    fast_error: float = 0.0
    drift_per_sample: float | None = None
    proved: bool = False
    proof: dict = field(default_factory=dict, compare=False)

    @property
    def xi_box(self) -> tuple[np.ndarray, np.ndarray]:
        return self.xi_lo.copy(), self.xi_hi.copy()

    def assumptions(self, base: Assumptions) -> Assumptions:
        """What a certifying run of this class assumes: ``base`` (the certification's bounds for one plan:
        ``t_s``, ``a_max``, ``xd0``, units) with this class's reading error, drift model and geometry box."""
        drift = None
        if self.drift_per_sample is not None:
            # d per sample as a rate, rounded up so that j t_s rate >= j d
            drift = (self.fast_error, float(np.nextafter(self.drift_per_sample / base.t_s, np.inf)))
        return base.with_(eps_q=self.reading_error, drift=drift, xi_box=self.xi_box)

    def summary(self) -> dict:
        return {
            "kind": self.kind.value,
            "reading_error": self.reading_error,
            "drift": self.drift,
            "fast_error": self.fast_error,
            "drift_per_sample": self.drift_per_sample,
            "xi_lo": self.xi_lo.tolist(),
            "xi_hi": self.xi_hi.tolist(),
            "derivation": self.derivation,
            "proved": self.proved,
            "proof": self.proof,
        }


def joint_error(eps_q: float, tracking_error: float = 0.0, *, down: bool = False) -> float:
    """``eps_q + tracking_error`` (joint units): how far the readings may lie from the planned joints.

    The one place the two are summed.  Rounded up for a class a certificate covers (every execution within
    the exact sum is in it); ``down=True`` rounds down, for a counterexample search, whose motion must lie
    within the exact sum.
    """
    lo, hi = I.add(eps_q, eps_q, tracking_error, tracking_error)
    return float(lo if down else hi)


def joint_class(robot, eps_q: float, tracking_error: float = 0.0) -> ExecutionClass:
    """Joints within ``eps_q + tracking_error`` (rad) of the plan, geometry in ``[xi]``."""
    bound = joint_error(eps_q, tracking_error)
    return ExecutionClass(ExecutionKind.JOINT, bound, 0.0, robot.xi_lo_array.copy(),
                          robot.xi_hi_array.copy(), {"source": "robot calibration box"},
                          bound, None, True,
                          {"proved": True, "method": "stated, not derived: eps_q + tracking_error and [xi] as given"})


def _offsets(robot):
    offs = getattr(robot, "joint_offsets", None) or (None,) * robot.n
    return [(i, j) for i, j in enumerate(offs) if j is not None]


def _geometries(robot, samples: int, rng) -> np.ndarray:
    """Corners of the non-offset parameters (at most 256, else random ones) and uniform samples of ``[xi]``."""
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    free = [k for k in range(lo.size) if k not in {j for _, j in _offsets(robot)} and hi[k] > lo[k]]
    rows = []
    if 2 ** len(free) <= 256:
        bits = itertools.product((0, 1), repeat=len(free))
    else:
        bits = (rng.integers(0, 2, len(free)) for _ in range(256))
    for b in bits:
        xi = 0.5 * (lo + hi)
        for k, bit in zip(free, b):
            xi[k] = hi[k] if bit else lo[k]
        rows.append(xi)
    rows.extend(lo + (hi - lo) * rng.random((samples, lo.size)))
    return np.array(rows)


def effective_deviation(kin, x_path, q_plan, xi_plan, xi) -> np.ndarray:
    """``q_k + delta - (q_plan,k + delta_plan)`` of an execution following ``x_path`` with geometry ``xi``.

    Parameters
    ----------
    x_path : array (K, n)
        Poses, SI.
    q_plan : array (K, n)
        Planned joints at those poses (planning geometry ``xi_plan``), rad.
    xi : array (m,)
        Geometry of the execution.

    Returns
    -------
    ndarray, shape (K, n), rad.  Offsets are added for the joints that have
    one (``Robot.joint_offsets``); the raw joint deviation otherwise.

    Raises
    ------
    SimulationError
        If the inverse kinematics from the planned joints does not converge at
        every pose, or jumps to another branch.
    """
    robot = kin.robot
    X = np.asarray(x_path, float)
    Qp = np.asarray(q_plan, float)
    Q, ok = kin.ik_batch(X, xi, Qp)
    if not np.all(ok):
        k = int(np.nonzero(~ok)[0][0])
        raise SimulationError(f"{robot.name}: inverse kinematics failed at path point {k} for geometry {[float(v) for v in xi]}")
    D = Q - Qp
    for i, j in _offsets(robot):
        D[:, i] += xi[j] - xi_plan[j]
    if np.max(np.abs(D)) > 0.2:
        raise SimulationError(f"{robot.name}: inverse kinematics left the planned branch for geometry {list(xi)}")
    return D


def cartesian_class(kin, x_path, q_plan, xi_plan, eps_q: float, tracking_error: float = 0.0, *,
                    samples: int = 32, seed: int = 0, safety: float = 1.25) -> ExecutionClass:
    """The ``cartesian`` class of one or several planned paths: ``C``, ``e`` and ``d``.

    For each geometry tried (every corner of the non-offset parameters and
    ``samples`` uniform draws in ``[xi]``), the effective deviation ``D_k``
    of :func:`effective_deviation` is split into its mid-range constant
    ``c`` and the drift ``D_k - c`` (``c = 0`` for a joint without an offset
    parameter: its whole deviation is drift).  ``e`` is ``safety`` times the largest
    drift met, ``d`` ``safety`` times the largest change of ``D`` between
    consecutive samples; ``C`` is ``delta_plan`` plus the hull of the
    constants, widened by ``(safety - 1)`` times its half-width plus
    ``eps_q`` on each side, and then by the robot's own offset interval
    (hull): the certifying run never assumes a narrower offset box than the
    run-time tracker has to.

    ``C``, ``e`` and ``d`` *define* the class (they are assumptions, measured,
    not proved): the certificate is sound for the class; whether an
    execution belongs to it is checked by :func:`in_class` (the Monte Carlo
    confirmation does, run by run).

    Parameters
    ----------
    x_path : array (K, n) or list of them
        Planned poses at consecutive samples, SI (several plans: one array
        each; ``d`` is taken within each).
    q_plan : array (K, n) or list of them
        Planned joints at ``x_path``, rad.
    xi_plan : array (m,)
        Planning geometry.
    eps_q, tracking_error : float
        Encoder bound and extra joint tracking error, rad.
    """
    robot = kin.robot
    if not safety >= 1.0:
        raise InputError(f"safety factor must be >= 1, got {safety}")
    xs = list(x_path) if isinstance(x_path, (list, tuple)) else [x_path]
    qs = list(q_plan) if isinstance(q_plan, (list, tuple)) else [q_plan]
    if len(xs) != len(qs):
        raise InputError("x_path and q_plan must hold as many paths")
    rng = np.random.default_rng(seed)
    xi_plan = np.asarray(xi_plan, float)
    X, Q = np.concatenate(xs), np.concatenate(qs)
    ends = np.cumsum([len(x) for x in xs])[:-1]
    offs = _offsets(robot)
    # a joint without an offset parameter has c = 0: its whole deviation is drift
    no_offset = np.array([i not in dict(offs) for i in range(robot.n)])
    consts, drifts, steps = [], [], []
    for xi in _geometries(robot, samples, rng):
        D = effective_deviation(kin, X, Q, xi_plan, xi)
        parts = np.split(D, ends)
        c = [np.where(no_offset, 0.0, 0.5 * (P.max(axis=0) + P.min(axis=0))) for P in parts]
        consts.extend(c)
        drifts.append(max(float(np.max(np.abs(P - ci))) for P, ci in zip(parts, c)))
        steps.append(max(float(np.max(np.abs(np.diff(P, axis=0)), initial=0.0)) for P in parts))
    consts = np.array(consts)
    drift = safety * max(drifts)
    step = safety * max(steps)
    lo, hi = robot.xi_lo_array.copy(), robot.xi_hi_array.copy()
    for i, j in offs:
        c_lo, c_hi = consts[:, i].min(), consts[:, i].max()
        pad = (safety - 1.0) * 0.5 * (c_hi - c_lo) + eps_q
        # never narrower than the robot's own offset interval: the certifying
        # run must not know the geometry better than the run-time tracker does
        lo[j] = min(xi_plan[j] + c_lo - pad, lo[j])
        hi[j] = max(xi_plan[j] + c_hi + pad, hi[j])
    derivation = {
        "geometries": int(len(drifts)),
        "paths": len(xs),
        "path_points": int(X.shape[0]),
        "largest_drift": float(max(drifts)),
        "largest_step": float(max(steps)),
        "constant_range": [[float(consts[:, i].min()), float(consts[:, i].max())] for i in range(robot.n)],
        "offset_box": "hull of the derived constants (widened) and the robot's offset intervals",
        "safety": float(safety),
        "seed": int(seed),
    }
    fast = joint_error(eps_q, tracking_error)
    reading = float(I.add(fast, fast, float(drift), float(drift))[1])
    return ExecutionClass(ExecutionKind.CARTESIAN, reading, float(drift), lo, hi, derivation, fast, float(step))


def in_class(cls: ExecutionClass, robot, q_true, q_plan, xi, xi_plan, eps_q: float, tracking_error: float = 0.0) -> bool:
    """Whether an execution with true joints ``q_true`` (K, n) and geometry ``xi`` belongs to ``cls``.

    ``joint``: ``|q_true - q_plan| <= eps_q + tracking_error`` and ``xi`` in the box.
    ``cartesian``: the lengths in the box, a constant ``c`` in ``C`` with
    ``|q_true + delta - q_plan - c| <= reading_error`` at every sample, and
    that deviation changing by at most ``2 fast_error + j drift_per_sample``
    over any ``j`` samples.
    """
    q_true, q_plan, xi = (np.asarray(a, float) for a in (q_true, q_plan, xi))
    lo, hi = cls.xi_lo, cls.xi_hi
    if cls.kind is ExecutionKind.JOINT:
        return bool(np.all(np.abs(q_true - q_plan) <= joint_error(eps_q, tracking_error))
                    and np.all((lo <= xi) & (xi <= hi)))
    offs = dict(_offsets(robot))
    others = [k for k in range(xi.size) if k not in offs.values()]
    if not np.all((lo[others] <= xi[others]) & (xi[others] <= hi[others])):
        return False
    # effective deviation q + delta - q_plan, joint by joint (delta = 0 without an offset parameter)
    dev = q_true + np.array([xi[offs[i]] if i in offs else 0.0 for i in range(robot.n)]) - q_plan
    if cls.drift_per_sample is not None:
        # |w_k - w_{k-j}| <= 2 fast_error + j d for every pair of samples (w = dev - c; c cancels)
        for j in range(1, dev.shape[0]):
            if np.any(np.abs(dev[j:] - dev[:-j]) > 2.0 * cls.fast_error + j * cls.drift_per_sample):
                return False
    for i in range(robot.n):
        d = dev[:, i]
        # the constant c must lie within reading_error of every d_k, and in C (0 without an offset)
        c_lo, c_hi = d.max() - cls.reading_error, d.min() + cls.reading_error
        if i in offs:
            c_lo, c_hi = max(c_lo, lo[offs[i]]), min(c_hi, hi[offs[i]])
        elif c_lo > 0.0 or c_hi < 0.0:
            return False
        if c_lo > c_hi:
            return False
    return True
