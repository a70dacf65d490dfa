"""IPOPT through CasADi, set up once for the planner's two nonlinear programs.

Both the crossing generator (:mod:`planner.generate`) and the counterexample
search (:mod:`planner.refute`) solve NLPs whose variable bounds are hard
facts (measurement intervals, joint limits): IPOPT must never relax them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca

__all__ = ["IpoptRun", "ParametricSolver", "STRICT_BOUNDS"]

#: Options of every solve: bounds are never relaxed (``bound_relax_factor = 0``)
#: and the solution honours them exactly; adaptive barrier update; no banner.
STRICT_BOUNDS = {"bound_relax_factor": 0.0, "honor_original_bounds": "yes", "mu_strategy": "adaptive", "sb": "yes"}


@dataclass(frozen=True, eq=False)
class IpoptRun:
    """One IPOPT solve: the CasADi solution dict, IPOPT's statistics, its status and the wall time (s)."""

    solution: dict
    stats: dict
    status: str
    elapsed_s: float


class ParametricSolver:
    """One IPOPT solver built once for ``min obj(z, p)`` s.t. ``lbg <= g(z, p) <= ubg``, ``lbx <= z <= ubx``.

    Building an ``nlpsol`` (the expression graph, its derivatives and IPOPT's
    set-up) costs as much as a short solve; data that change between solves
    of one problem family (readings, bounds, scales) enter as the parameter
    vector ``p``, so one solver serves every instance of the family.

    Parameters
    ----------
    name : str
        Name of the CasADi solver.
    z, p, obj, g : casadi.SX
        Variables, parameters, objective and constraints.
    ipopt : dict
        IPOPT options on top of :data:`STRICT_BOUNDS`.
    """

    def __init__(self, name: str, z, p, obj, g, *, ipopt: dict):
        self._solver = ca.nlpsol(name, "ipopt", {"x": z, "p": p, "f": obj, "g": g},
                                 {"ipopt": {**STRICT_BOUNDS, **ipopt}, "print_time": False})
        self.n_variables, self.n_constraints = int(z.numel()), int(g.numel())

    def solve(self, *, p, z0, lbx, ubx, lbg, ubg) -> IpoptRun:
        """Solve the instance of parameters ``p`` from ``z0``."""
        t0 = time.perf_counter()
        sol = self._solver(x0=z0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        elapsed = time.perf_counter() - t0
        stats = self._solver.stats()
        return IpoptRun(sol, stats, str(stats.get("return_status", "unknown")), elapsed)
