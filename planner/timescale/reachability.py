"""The fastest admissible crossing speed by toppra's reachability analysis.

:func:`max_speed_at` builds toppra constraints with the same discretisation as
:func:`~planner.timescale.time_optimal_scaling` (exact path derivatives at the
nodes, interpolation scheme for the acceleration-level bounds), so both agree
up to solver tolerances.
"""

from __future__ import annotations

import math

import numpy as np
import toppra
from scipy.interpolate import BPoly
from toppra.constraint import (
    DiscretizationType,
    JointAccelerationConstraint,
    JointVelocityConstraint,
    LinearConstraint,
    canlinear_colloc_to_interpolate,
)

from crosscert.robots.errors import InputError, SimulationError

from .limits import ScalingLimits, check_nodes, per_joint
from .path import PathSamples, criterion_coeffs, crossing_direction, node_index

__all__ = ["max_speed_at"]


class HermitePath(toppra.interpolator.AbstractGeometricPath):
    """C^2 joint path through exact ``(q, q', q'')`` at the nodes (quintic Hermite).

    toppra evaluates the path only at the grid nodes here, so its constraint
    coefficients are the exact kinematic derivatives, as in the cvxpy problem
    (a cubic spline through ``q`` alone would differ by its interpolation error).
    Between nodes it is the IK starting guess of :func:`~planner.timescale.resample`.

    Parameters
    ----------
    s : ndarray, shape (N + 1,)
        Nodes, m.
    q, q_s, q_ss : ndarray, shape (N + 1, n)
        Joints (rad) and their first (rad/m) and second (rad/m^2) derivatives.
    """

    def __init__(self, s: np.ndarray, q: np.ndarray, q_s: np.ndarray, q_ss: np.ndarray):
        self._s = s
        self._polys = [BPoly.from_derivatives(s, np.stack([q[:, j], q_s[:, j], q_ss[:, j]], axis=1))
                       for j in range(q.shape[1])]
        self._d = [[p, p.derivative(1), p.derivative(2)] for p in self._polys]

    def __call__(self, path_positions, order=0):
        if order not in (0, 1, 2):
            raise ValueError(f"order must be 0, 1 or 2, got {order}")
        return np.stack([d[order](path_positions) for d in self._d], axis=-1)

    @property
    def dof(self) -> int:
        return len(self._polys)

    @property
    def path_interval(self):
        return np.array([self._s[0], self._s[-1]])


class _GridConstraint(LinearConstraint):
    """toppra canonical linear constraint ``F (a_i u + b_i x + c_i) <= g`` from node arrays."""

    def __init__(self, s, a, b, c, F, g, *, interpolate: bool):
        super().__init__()
        self._s, self._a, self._b, self._c, self._F, self._g = s, a, b, c, F, g
        self.identical = F.ndim == 2
        self.dof = -1  # path-independent: the data are given on the grid
        self.set_discretization_type(DiscretizationType.Interpolation if interpolate
                                     else DiscretizationType.Collocation)

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        if gridpoints.shape != self._s.shape or np.any(gridpoints != self._s):
            raise ValueError("this constraint is defined on the samples' grid only")
        if self.discretization_type == DiscretizationType.Collocation:
            return self._a, self._b, self._c, self._F, self._g, None, None
        return canlinear_colloc_to_interpolate(self._a, self._b, self._c, self._F, self._g, None,
                                               None, gridpoints, identical=self.identical)


def max_speed_at(samples: PathSamples, limits: ScalingLimits, s_star: float, *,
                 rest_to_rest: bool = True, criterion: bool = True,
                 criterion_direction=None) -> float:
    """Largest speed at ``s_star`` of any admissible scaling (toppra reachability), m/s.

    toppra's controllable sets ``K_i`` (states from which the end can be
    reached within the limits) and reachable sets ``L_i`` (states reachable
    from the start) are computed on the samples' grid; the speeds at node
    ``i`` lying on a complete admissible scaling are exactly ``K_i ∩ L_i``,
    so the answer is ``sqrt(min(max K_k, max L_k))`` at the node ``k`` nearest
    ``s_star``.  Constraints: :class:`toppra.constraint.JointVelocityConstraint`,
    :class:`toppra.constraint.JointAccelerationConstraint` on a joint path
    with the exact derivatives at the nodes, and canonical linear constraints
    (interpolation scheme, like :func:`~planner.timescale.time_optimal_scaling`)
    for the end-effector acceleration and ``limits.extra``; the crossing
    criterion at ``s*`` (see :func:`~planner.timescale.time_optimal_scaling`)
    as an equality on the two adjacent stages.  This is the upper end of a
    ``v_sing`` search.

    Parameters
    ----------
    samples : PathSamples
        ``N + 1`` nodes.
    limits : ScalingLimits
    s_star : float
        Arc length of the crossing, m (the nearest node is used).
    rest_to_rest : bool
        Start and end at rest; otherwise the end speeds are free.
    criterion : bool
        Impose the crossing criterion at the node.
    criterion_direction : array_like, shape (n,), optional
        As in :func:`~planner.timescale.time_optimal_scaling`.

    Returns
    -------
    float
        m/s.

    Raises
    ------
    InputError
        Malformed arguments.
    SimulationError
        No admissible scaling reaches the node (toppra's sets are empty).
    """
    if not isinstance(samples, PathSamples):
        raise InputError(f"samples must be PathSamples, got {type(samples).__name__}")
    if not isinstance(limits, ScalingLimits):
        raise InputError(f"limits must be ScalingLimits, got {type(limits).__name__}")
    k = node_index(samples, s_star, exact=False)
    N, s = samples.n_intervals, samples.s
    path = HermitePath(s, samples.q, samples.q_s, samples.q_ss)
    cons = _limit_constraints(samples, limits)
    if criterion:
        cons.append(_criterion_constraint(samples, k, criterion_direction))
    if not cons:
        raise InputError("max_speed_at needs at least one limit")
    algo = toppra.algorithm.TOPPRA(cons, path, gridpoints=np.array(s), solver_wrapper="seidel")
    if rest_to_rest:
        K = algo.compute_controllable_sets(0.0, 0.0)
        Lr = algo.compute_reachable_sets(0.0, 0.0)
    else:
        X = algo.compute_feasible_sets()
        K = algo.compute_controllable_sets(0.0, math.sqrt(max(X[N, 1], 0.0)))
        Lr = algo.compute_reachable_sets(0.0, math.sqrt(max(X[0, 1], 0.0)))
    top = min(K[k, 1], Lr[k, 1])
    if not (np.isfinite(top) and K[k, 0] <= K[k, 1] and Lr[k, 0] <= Lr[k, 1]):
        raise SimulationError(
            f"no admissible scaling of the path reaches s* = {s[k]:.6g} m under the limits")
    return math.sqrt(max(float(top), 0.0))


def _limit_constraints(samples: PathSamples, limits: ScalingLimits) -> list:
    """toppra constraints of the limits: joint velocity and acceleration, end-effector acceleration, extra rows.

    The end-effector acceleration ``|x' sddot + x'' sdot^2| <= a_max`` (m/s^2)
    and each ``limits.extra`` row are canonical linear constraints on the
    samples' grid (interpolation scheme).

    Raises
    ------
    InputError
        Malformed limits.
    """
    n, N, s = samples.q.shape[1], samples.n_intervals, samples.s
    cons = []
    qd = per_joint(limits.qd_max, n, "qd_max")
    qdd = per_joint(limits.qdd_max, n, "qdd_max")
    am = per_joint(limits.a_max, n, "a_max")
    if qd is not None:
        cons.append(JointVelocityConstraint(qd))
    if qdd is not None:
        cons.append(JointAccelerationConstraint(qdd))
    if am is not None:
        F = np.vstack([np.eye(n), -np.eye(n)])
        cons.append(_GridConstraint(s, samples.x_s, samples.x_ss, np.zeros((N + 1, n)), F,
                                    np.concatenate([am, am]), interpolate=True))
    for e in limits.extra:
        check_nodes(e, N + 1)
        kk = e.A.shape[1]
        F = np.broadcast_to(np.eye(kk), (N + 1, kk, kk)).copy()
        cons.append(_GridConstraint(s, e.A, e.B, np.zeros_like(e.A), F, np.array(e.C), interpolate=True))
    return cons


def _criterion_constraint(samples: PathSamples, k: int, criterion_direction) -> _GridConstraint:
    """The crossing criterion at node ``k`` as an equality on the two adjacent stages (collocation).

    Raises
    ------
    InputError
        A malformed criterion direction, or one normal to the path.
    """
    N, ds = samples.n_intervals, samples.ds
    cx, cxx = criterion_coeffs(samples, k, crossing_direction(samples, k, criterion_direction))
    ca_, cb_ = np.zeros((N + 1, 1)), np.zeros((N + 1, 1))
    if k < N:  # stage k: cx u_k + cxx x_k = 0
        ca_[k, 0], cb_[k, 0] = cx, cxx
    if k > 0:  # stage k-1, written on x_k = x_{k-1} + 2 ds u_{k-1}
        ca_[k - 1, 0], cb_[k - 1, 0] = cx + 2.0 * ds * cxx, cxx
    return _GridConstraint(samples.s, ca_, cb_, np.zeros((N + 1, 1)), np.array([[1.0], [-1.0]]),
                           np.zeros(2), interpolate=False)
