"""The ``cartesian`` execution class proved by interval analysis over the whole calibration box.

:func:`planner.execution.cartesian_class` *measures* the class's ``C``,
``e`` and ``d`` on sampled geometries.  :func:`prove_cartesian_class`
bounds the same quantities for every geometry of ``[xi]`` at once, so that
every execution following the planned path is in the class by construction.

The argument, step by step (docs/soundness.md, "The execution class of a
certificate"):

1. *Effective joints.*  With ``Robot.joint_offsets`` (``f`` reads joint
   ``i`` only through ``u_i = q_i + xi_j``) the loop closure is rewritten in
   ``u`` by substituting ``q_i = u_i - xi_j`` in the robot's one CasADi
   definition; CasADi must then report that it no longer depends on the
   offsets (``depends_on``), else nothing is proved.  The effective
   deviation ``D_k(xi) = u_k(xi) - u_plan,k`` therefore depends only on the
   other parameters: the offsets drop out of ``C``, ``e`` and ``d``.  A joint
   without an offset parameter keeps ``u_i = q_i`` (in its own unit, rad or
   m) and its whole deviation is drift (``c_i = 0`` exactly).
2. *The branch.*  At each planned pose ``x_k`` the box
   ``U_k = u_plan,k +- r_k`` is inflated until the Krawczyk image over the
   whole box ``[xi]`` lies strictly inside it: then every geometry has
   exactly one root in ``U_k`` (the plan's branch: the planned joints are
   the root at the planning geometry), ``J_u`` is regular there, and the
   root ``u_k(xi)`` is continuously differentiable.  No inflation proved:
   ``proved: false`` with the sample.
3. *Mean-value forms.*  On a sub-box ``B`` of the free parameters with
   centre ``c``: ``u_k(c)`` is enclosed by a box Krawczyk proves at the
   point ``c``, the slope ``G_k = du_k/dxi`` over ``U_k x B`` by the interval
   solution of ``J_u G = -J_xi``.  Then for every ``xi`` in ``B``::

       D_k(xi) - D_r(xi)     in  D_k(c) - D_r(c)     + (G_k - G_r)(B) (B - c)
       D_k(xi) - D_{k-1}(xi) in  D_k(c) - D_{k-1}(c) + S_k (B - c)

   for a reference sample ``r`` (the middle one), where ``S_k`` is
   ``(G_k - G_{k-1})(B)`` intersected with the slope's change along the
   segment ``x_{k-1} -> x_k`` proved once over ``[xi]``
   (:func:`verifier.implicit.slope_change`).  For an offset joint, with
   ``m`` the midpoint of the hull of the first enclosure over ``k``, the
   constant ``c = D_r(xi) + m`` lies in ``D_r(B) + m`` and ``|D_k - c|`` is
   at most the larger distance from ``m`` to that hull
   (:func:`offset_split`): the box's ``C`` and ``e``; ``d`` is the largest
   magnitude of the second enclosure.
4. *Branch and bound*, one per joint, best first.  A sub-box is bisected
   along the parameter whose remainder exceeds the linear part most, until
   every leaf's bounds are within ``tol`` (relative) of the largest values
   met at evaluated geometries (box centres and the corners the
   linearisation points to), the exact termination rule, or until
   ``max_boxes`` sub-boxes were evaluated (the bounds are proved either way;
   only their tightness differs).  The class takes the hull of the leaves'
   ``C`` and the largest ``e`` and ``d``: the leaves partition ``[xi]``.
   The joints' searches run in lockstep, each round's sub-boxes of all of
   them evaluated in one call (each distinct one once): the bounds are
   those of the searches run one by one, bit for bit.

Every operation is outward-rounded (:mod:`verifier.interval`); an empty
enclosure contradicts step 2 and is reported as ``proved: false``
(inconsistent), never as a bound.  Nothing here names a robot.

Steps 2 to 4 run in :mod:`planner.execution_search`; this module states
the result (:class:`ClassProof`, :func:`prove_cartesian_class`) and builds
the class from it (:func:`proved_class`, :func:`execution_class`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from crosscert.robots.errors import InputError
from crosscert.verifier import interval as I

from .execution import ExecutionClass, ExecutionKind, cartesian_class, joint_class, joint_error
from .execution_search import branch_and_bound_joints, loop_closure_tapes, offset_joints, offset_split, setup_path
from .task import PlannedTrajectory, resolved

__all__ = ["METHOD", "ClassProof", "prove_cartesian_class", "prove_cartesian_class_cached", "proved_class",
           "with_proof_failure", "describe", "offset_split", "execution_class"]

#: How the bounds are proved (reported in certificate.json).
METHOD = ("interval branch and bound over [xi]: Krawczyk-proved IK enclosures, mean-value forms with "
          "interval slopes du/dxi, outward rounding")


@dataclass(frozen=True, eq=False)
class ClassProof:
    """Outcome of :func:`prove_cartesian_class`.

    Attributes
    ----------
    proved : bool
    reason : str
        Why not proved (empty when proved).
    c_lo, c_hi : ndarray, shape (n,)
        Proved enclosure of the constant part per joint (rad, or m for a
        prismatic joint; exactly 0 for a joint without an offset parameter).
    drift : float
        ``e``: proved bound on ``|D_k - c|``.
    step : float
        ``d``: proved bound on the change of ``D`` per sample.
    boxes : int
        Sub-boxes of ``[xi]`` evaluated by the branch and bound.
    time_s : float
        Wall time of the proof, s.
    found : dict
        Largest values met at evaluated geometries (lower bounds of the true
        maxima): ``drift``, ``step``, ``c_lo``, ``c_hi`` and the geometries
        (full ``xi`` vectors) where the drift and step maxima were met.
    converged : bool
        Whether the termination rule was met (``False``: the box budget ran
        out first; the bounds are proved but may be looser than ``tol``).
    tol : float
        Relative tolerance of that rule.
    """

    proved: bool
    reason: str = ""
    c_lo: np.ndarray = field(default_factory=lambda: np.zeros(0))
    c_hi: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drift: float = float("nan")
    step: float = float("nan")
    boxes: int = 0
    time_s: float = 0.0
    found: dict = field(default_factory=dict)
    converged: bool = False
    tol: float = 0.0

    def summary(self) -> dict:
        """The ``execution.proof`` object of certificate.json."""
        if not self.proved:
            return {"proved": False, "reason": self.reason, "time_s": self.time_s}
        return {"proved": True, "method": METHOD, "boxes_explored": self.boxes, "time_s": self.time_s,
                "converged": self.converged, "tolerance": self.tol,
                "largest_drift_found": self.found.get("drift"),
                "largest_step_found": self.found.get("step")}


def prove_cartesian_class(robot, x_path, q_plan, xi_plan, *, tol: float = 0.05, max_boxes: int = 16,
                          remainder: bool = True) -> ClassProof:
    """Prove ``C``, ``e`` and ``d`` of the ``cartesian`` class over the whole box ``[xi]`` (module docstring).

    Parameters
    ----------
    robot : Robot
    x_path : array (K, n) or list of them
        Planned poses at consecutive samples, SI.
    q_plan : array (K, n) or list of them
        Planned joints there (planning geometry ``xi_plan``), rad (m for a prismatic joint).
    xi_plan : array (m,)
        Planning geometry, SI.
    tol : float
        Relative tolerance of the termination rule: a sub-box is settled when
        its bounds exceed the largest values met at evaluated geometries by
        at most ``tol`` times them (``C``: times the width of the range met).
    max_boxes : int
        Budget of evaluated sub-boxes per path and joint (the bounds are
        proved when it runs out too, only possibly looser than ``tol``).
    remainder : bool
        Keep the remainder term of the mean-value forms.  ``False`` only for
        the tests' removal check: the bounds are then *not* proved.

    Returns
    -------
    ClassProof
        ``proved`` false (with the reason) when the model is not supported or
        an inverse kinematics enclosure could not be proved.
    """
    t0 = time.perf_counter()
    xs = list(x_path) if isinstance(x_path, (list, tuple)) else [x_path]
    qs = list(q_plan) if isinstance(q_plan, (list, tuple)) else [q_plan]
    built, why = loop_closure_tapes(robot)
    if built is None:
        return ClassProof(False, why, time_s=time.perf_counter() - t0)
    tapes, free, numeric = built
    if not free:
        return ClassProof(False, "no parameter of the loop closure has a calibration interval wider than a point: "
                                 "nothing to branch on (not supported)", time_s=time.perf_counter() - t0)
    offs = offset_joints(robot)
    xi_plan = np.asarray(xi_plan, float)
    n = robot.n
    c_lo, c_hi = np.zeros(n), np.zeros(n)
    e = d = 0.0
    found = {"drift": 0.0, "step": 0.0, "c_lo": np.zeros(n), "c_hi": np.zeros(n), "drift_xi": None, "step_xi": None}
    boxes, converged = 0, True
    with I.quiet_fp():
        for x, q in zip(xs, qs):
            x, q = np.asarray(x, float), np.asarray(q, float)
            off = np.array([xi_plan[offs[i]] if i in offs else 0.0 for i in range(n)])
            u_plan = I.add(q, q, off, off)  # outward: the deviation D_k is taken from this enclosure
            path = setup_path(tapes, numeric, robot, free, x, u_plan, remainder)
            if isinstance(path, str):
                return ClassProof(False, path, time_s=time.perf_counter() - t0)
            # one branch and bound per joint: each splits only the parameters its own bounds need
            for i, res in enumerate(branch_and_bound_joints(path, tol, max_boxes, range(n))):
                if isinstance(res, str):
                    return ClassProof(False, res, time_s=time.perf_counter() - t0)
                boxes += res["boxes"]
                converged &= res["converged"]
                c_lo[i], c_hi[i] = min(c_lo[i], res["c_lo"]), max(c_hi[i], res["c_hi"])
                e, d = max(e, res["e"]), max(d, res["d"])
                f = res["found"]
                if f["drift"] >= found["drift"]:
                    found.update(drift=f["drift"], drift_xi=f["drift_xi"])
                if f["step"] >= found["step"]:
                    found.update(step=f["step"], step_xi=f["step_xi"])
                found["c_lo"][i] = min(found["c_lo"][i], f["c_lo"])
                found["c_hi"][i] = max(found["c_hi"][i], f["c_hi"])
    return ClassProof(True, "", c_lo, c_hi, float(e), float(d), boxes, time.perf_counter() - t0, found, converged,
                      float(tol))



#: Proofs of recent plans: a plan's class depends only on the plan and the robot (the speed
#: search at the robot's own a_max asks again for plans already proved).
_CACHE: dict = {}
_CACHE_SIZE = 64


def prove_cartesian_class_cached(robot, x_path, q_plan, xi_plan) -> ClassProof:
    """:func:`prove_cartesian_class` with its defaults, remembered per robot and plan (exact bytes)."""
    xs = list(x_path) if isinstance(x_path, (list, tuple)) else [x_path]
    qs = list(q_plan) if isinstance(q_plan, (list, tuple)) else [q_plan]
    key = (id(robot), robot.name, tuple(np.asarray(a, float).tobytes() for a in (*xs, *qs, xi_plan)))
    hit = _CACHE.get(key)
    if hit is not None and hit[0] is robot:
        return hit[1]
    proof = prove_cartesian_class(robot, xs, qs, xi_plan)
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = (robot, proof)
    return proof


def describe(cls: ExecutionClass, joint_unit: str = "joint units") -> str:
    """One line about how the class's bounds were obtained (``crosscert certify`` prints it)."""
    if cls.kind is not ExecutionKind.CARTESIAN:
        return f"execution class: {cls.kind.value} (stated, nothing derived)"
    e, d = cls.drift, cls.drift_per_sample
    if cls.proved:
        pr = cls.proof
        return (f"execution class: cartesian, C, e and d proved for every geometry of [xi] (interval branch and "
                f"bound, {pr.get('boxes_explored')} boxes, {pr.get('time_s', 0.0):.2f} s): e = {e:.4g}, d = {d:.4g} "
                f"per sample ({joint_unit})")
    return (f"execution class: cartesian, C, e and d measured on sampled geometries, NOT proved "
            f"({cls.proof.get('reason', 'no proof')}): e = {e:.4g}, d = {d:.4g} per sample ({joint_unit})")


def proved_class(robot, proof: ClassProof, xi_plan, eps_q: float, tracking_error: float = 0.0) -> ExecutionClass:
    """The ``cartesian`` :class:`ExecutionClass` of a successful proof.

    ``C`` is ``delta_plan`` plus the proved constant range, outward rounded,
    and hulled with the robot's own offset intervals (as the measured class:
    the certifying run never assumes a narrower offset box than the run-time
    tracker has to); ``e`` and ``d`` as proved; nothing is widened by a
    safety factor.
    """
    if not proof.proved:
        raise InputError(f"proved_class needs a successful proof, got one not proved: {proof.reason}")
    xi_plan = np.asarray(xi_plan, float)
    lo, hi = robot.xi_lo_array.copy(), robot.xi_hi_array.copy()
    for i, j in offset_joints(robot).items():
        cl, ch = I.add(xi_plan[j], xi_plan[j], proof.c_lo[i], proof.c_hi[i])
        lo[j], hi[j] = min(float(cl), lo[j]), max(float(ch), hi[j])
    fast = joint_error(eps_q, tracking_error)
    reading = float(I.add(fast, fast, proof.drift, proof.drift)[1])
    derivation = {
        "constant_range": [[float(a), float(b)] for a, b in zip(proof.c_lo, proof.c_hi)],
        "largest_drift": proof.drift,
        "largest_step": proof.step,
        "largest_drift_found": proof.found.get("drift"),
        "largest_step_found": proof.found.get("step"),
        "offset_box": "hull of the proved constants and the robot's offset intervals",
    }
    return ExecutionClass(ExecutionKind.CARTESIAN, reading, proof.drift, lo, hi, derivation, fast, proof.step,
                          proved=True, proof=proof.summary())


def with_proof_failure(cls: ExecutionClass, proof: ClassProof) -> ExecutionClass:
    """A measured class marked ``proved: false`` with the proof's reason."""
    return replace(cls, proved=False, proof=proof.summary())


def execution_class(kin, plans, bounds) -> ExecutionClass:
    """The admissible executions of one plan or a list of plans (union of their paths) under ``bounds``
    (:class:`planner.task.ResolvedBounds` for ``kin.robot``, or a :class:`~planner.task.PlanningBounds`
    resolved here).

    See :mod:`planner.execution`; ``cartesian`` classes are proved over the
    whole box ``[xi]`` (:mod:`planner.execution_proof`) and, when the proof
    is not available for the robot's model, measured on sampled geometries
    (seeded, deterministic) and marked ``proved: false`` with the reason.
    """
    robot = kin.robot
    b = resolved(bounds, robot)
    if b.execution is ExecutionKind.JOINT:
        return joint_class(robot, b.eps_q, b.tracking_error)
    plans = [plans] if isinstance(plans, PlannedTrajectory) else list(plans)
    xs, qs = [p.x for p in plans], [p.q for p in plans]
    proof = prove_cartesian_class_cached(robot, xs, qs, plans[0].xi_plan)
    if proof.proved:
        return proved_class(robot, proof, plans[0].xi_plan, b.eps_q, b.tracking_error)
    return with_proof_failure(cartesian_class(kin, xs, qs, plans[0].xi_plan, b.eps_q, b.tracking_error), proof)
