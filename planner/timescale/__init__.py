"""Time scaling of a straight crossing path under kinematic limits (planning-time certification).

The end-effector follows ``x(s) = p0 + s u``, ``s in [0, L]`` (m), ``u`` a unit
vector, through a point of the Type 2 singular locus at ``s = s*``.  A time
scaling ``s(t)`` lives on a grid ``s_0 = 0 < ... < s_N = L`` of step ``ds``:
``b_i = sdot(s_i)^2`` (m^2/s^2) at the nodes and ``a_i = sddot`` (m/s^2)
constant on ``[s_i, s_{i+1}]``, so ``b_{i+1} = b_i + 2 ds a_i`` and ``s(t)`` is
piecewise quadratic (the classic TOPP discretisation).

By the chain rule every bound is linear in ``(a, b)``:
``q'^2 b <= qd_max^2``, ``|q' a + q'' b| <= qdd_max``, ``|x' a + x'' b| <= a_max``,
``'`` the derivative in ``s``.  ``q'`` and ``q''`` are exact (eq. (2) of the
paper and its derivative), finite on the Type 2 locus since only ``J_q`` is
inverted.  An interval's ``a_i`` meets the bounds of *both* end nodes
(toppra's "interpolation" scheme); between nodes the end-effector bound holds
exactly on a straight path, joint bounds up to ``O(ds^2)``.

Modules, along the method:

* :mod:`.path`: :func:`sample_path` (a segment) and :func:`sample_curve` (a given path), the grid and its exact derivatives;
* :mod:`.limits`: :class:`ScalingLimits`, :class:`LinearPathConstraint` and their rows;
* :mod:`.socp`: :func:`time_optimal_scaling`, the minimum-time scaling crossing
  ``s*`` at a prescribed ``v_sing`` under the crossing criterion (cvxpy
  second-order cone program);
* :mod:`.reachability`: :func:`max_speed_at`, the largest admissible speed at
  ``s*`` (toppra), the upper end of a ``v_sing`` search;
* :mod:`.resampling`: :func:`resample`, the fixed-period joint trajectory for
  the tracker and the simulator.

Both solvers share the discretisation, so they agree up to solver
tolerances.  SI units throughout (m, rad, s).
"""

from .limits import LinearPathConstraint, ScalingLimits
from .path import PathSamples, sample_curve, sample_path
from .reachability import max_speed_at
from .resampling import TimedTrajectory, resample
from .socp import FEAS_RTOL, TimeScaling, time_optimal_scaling

__all__ = [
    "FEAS_RTOL",
    "LinearPathConstraint",
    "PathSamples",
    "ScalingLimits",
    "TimeScaling",
    "TimedTrajectory",
    "max_speed_at",
    "resample",
    "sample_curve",
    "sample_path",
    "time_optimal_scaling",
]
