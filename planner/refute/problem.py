"""What a counterexample search takes and gives: bounds, candidates, outcomes.

A counterexample ("bounce") for a recording is a motion satisfying every
assumption a sound tracker makes about that recording that keeps the assembly
mode of its first sample:

* one constant geometry ``xi`` inside the calibration box ``[xi_lo, xi_hi]``;
* a pose ``x(t)`` that is exactly C^1 and piecewise quadratic on the sample
  grid ``t_k = k t_s``: on ``[t_k, t_k+1]`` the acceleration is the constant
  ``u_k`` with ``|u_k,i| <= a_max_i``, so ``x_k+1 = x_k + t_s v_k + t_s^2/2 u_k``
  and ``v_k+1 = v_k + t_s u_k`` hold exactly (not a discretisation);
* joints ``q_k`` with ``f(x_k, q_k, xi) = 0`` and ``|q_k - q_meas[k]| <= eps_q``
  at every sample;
* the assembly mode (``KinematicModel.mode``, i.e. ``mode_sign * sign det J_x``)
  equal to the initial mode ``m0`` at every sample;
* optionally ``|x'(0)| <= v0_max``, ``|x'(t)| <= v_max``, ``x(t)`` in the
  robot's workspace box (the tracker's other assumptions).

A *crossing* counterexample, for a recording a tracker might certify
``mode-unchanged`` (e.g. a bounce), satisfies the same assumptions except the
one on the modes: mode ``m0`` at the first sample and ``-m0`` at the last
(anything in between).  :class:`CounterexampleKind` names the two.

This module holds the types of that problem (:class:`RecordingBounds`) and of
a candidate (:class:`Counterexample`, with the motion it stands for,
:func:`integrate_states`), the NLP's safety margins, and the words for how a
search ended (:class:`SearchOutcome`); the result records are in
:mod:`planner.refute.results`.  SI units throughout (m, rad, s).
"""

from __future__ import annotations

from dataclasses import InitVar, dataclass
from enum import StrEnum
from types import MappingProxyType

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.assumptions import UNSET, Assumptions, held, reader
from crosscert.robots.errors import InputError
from crosscert.robots.kinematics import KinematicModel

__all__ = [
    "ACCEL_MARGIN",
    "IPOPT_OUTCOMES",
    "JOINT_MARGIN",
    "MODE_MARGIN",
    "XI_MARGIN",
    "Counterexample",
    "CounterexampleKind",
    "RecordingBounds",
    "SearchOutcome",
    "integrate_states",
    "ipopt_outcome",
]

#: The NLP's joint intervals are ``q_meas +- (1 - JOINT_MARGIN) eps_q``, so the
#: verified joints lie strictly inside ``q_meas +- eps_q`` despite IPOPT's
#: constraint tolerance and the re-solved IK (both ~1e-10 of eps_q).
JOINT_MARGIN = 1e-4
#: The NLP's bounds on ``|u|`` are ``(1 - ACCEL_MARGIN) a_max`` (also for v0_max, v_max).
ACCEL_MARGIN = 1e-6
#: The NLP's geometry box is shrunk by this fraction of its half-width.
XI_MARGIN = 1e-6
#: The NLP requires ``m0 * mode_sign * det J_x >= MODE_MARGIN * prod_i |row_i J_x|``
#: (Hadamard's bound); the verification's threshold is ``robots.kinematics.MODE_RTOL`` = 1e-10.
MODE_MARGIN = 1e-6


# ------------------------------------------------------------------ kinds
class CounterexampleKind(StrEnum):
    """Which verdict a counterexample refutes, i.e. what it requires of the modes at the samples.

    Both kinds start in the recording's initial mode ``m0`` and share every
    other assumption (geometry box, ``a_max``, joint intervals, ...).
    """

    #: Mode ``m0`` at every sample: the readings are explained without a mode
    #: change, so no sound tracker may certify ``mode-changed`` on them.
    BOUNCE = "bounce"
    #: Mode ``m0`` at the first sample and ``-m0`` at the last: the readings are
    #: explained by a motion that changed mode, so no sound tracker may certify
    #: ``mode-unchanged`` on them (a tracker's verdict compares the first and
    #: last samples' modes, ``verifier.tracker.verdict_of``).
    CROSSING = "crossing"

    @property
    def refutes(self) -> str:
        """The verdict (``verifier.Verdict`` value) this kind of counterexample rules out."""
        return "mode-changed" if self is CounterexampleKind.BOUNCE else "mode-unchanged"


# ------------------------------------------------------------------ outcome
class SearchOutcome(StrEnum):
    """How one counterexample search ended, in our words rather than IPOPT's.

    Only :attr:`FOUND` is a counterexample.  Every other member means that this
    search found none, and *never* that none exists: the NLP is non-convex and
    IPOPT is a local solver, so even :attr:`INFEASIBLE` is a statement about
    the neighbourhood IPOPT explored from its starting point, not a proof.
    """

    #: IPOPT converged and the independent check (``verify_bounce`` or
    #: ``verify_crossing``) accepted the candidate.
    FOUND = "counterexample-found"
    #: IPOPT converged but the independent check refused the candidate.
    REJECTED = "candidate-rejected"
    #: IPOPT converged; the candidate has not been checked (all an IPOPT status can say).
    CONVERGED = "converged-unverified"
    #: IPOPT converged to a point that locally minimises the constraint violation.
    INFEASIBLE = "locally-infeasible"
    #: IPOPT stopped without converging (step too small, restoration failed, diverging iterates).
    NOT_CONVERGED = "not-converged"
    #: IPOPT hit its iteration cap.
    ITERATION_LIMIT = "iteration-limit"
    #: IPOPT hit its CPU or wall time cap.
    TIME_LIMIT = "time-limit"
    #: IPOPT refused the problem or failed internally, or returned a status we do not know.
    SOLVER_ERROR = "solver-error"
    #: No NLP was solved (e.g. no recording could be made at that speed).
    NOT_SEARCHED = "not-searched"


#: Every ``return_status`` CasADi reports for IPOPT 3.14, and what it means here.
IPOPT_OUTCOMES = MappingProxyType({
    "Solve_Succeeded": SearchOutcome.CONVERGED,
    "Solved_To_Acceptable_Level": SearchOutcome.CONVERGED,
    "Infeasible_Problem_Detected": SearchOutcome.INFEASIBLE,
    "Search_Direction_Becomes_Too_Small": SearchOutcome.NOT_CONVERGED,
    "Diverging_Iterates": SearchOutcome.NOT_CONVERGED,
    "Restoration_Failed": SearchOutcome.NOT_CONVERGED,
    "Error_In_Step_Computation": SearchOutcome.NOT_CONVERGED,
    "Maximum_Iterations_Exceeded": SearchOutcome.ITERATION_LIMIT,
    "Maximum_CpuTime_Exceeded": SearchOutcome.TIME_LIMIT,
    "Maximum_WallTime_Exceeded": SearchOutcome.TIME_LIMIT,
    # Only returned for square problems or with a user callback; the NLP has neither.
    "Feasible_Point_Found": SearchOutcome.SOLVER_ERROR,
    "User_Requested_Stop": SearchOutcome.SOLVER_ERROR,
    "Not_Enough_Degrees_Of_Freedom": SearchOutcome.SOLVER_ERROR,
    "Invalid_Problem_Definition": SearchOutcome.SOLVER_ERROR,
    "Invalid_Option": SearchOutcome.SOLVER_ERROR,
    "Invalid_Number_Detected": SearchOutcome.SOLVER_ERROR,
    "Unrecoverable_Exception": SearchOutcome.SOLVER_ERROR,
    "NonIpopt_Exception_Thrown": SearchOutcome.SOLVER_ERROR,
    "Insufficient_Memory": SearchOutcome.SOLVER_ERROR,
    "Internal_Error": SearchOutcome.SOLVER_ERROR,
})


def ipopt_outcome(status: str) -> SearchOutcome:
    """The :class:`SearchOutcome` of an IPOPT ``return_status`` string.

    Both success statuses give :attr:`SearchOutcome.CONVERGED` (a candidate,
    not yet a counterexample); an unknown status gives
    :attr:`SearchOutcome.SOLVER_ERROR`.
    """
    return IPOPT_OUTCOMES.get(status, SearchOutcome.SOLVER_ERROR)


# ------------------------------------------------------------------ inputs
#: RecordingBounds' names of the fields of its Assumptions.
_ASSUMED = {"t_s": "t_s", "eps_q": "eps_q", "a_max": "a_max", "xi_lo": "xi_lo", "xi_hi": "xi_hi",
            "v0_max": "xd0", "v_max": "v_max"}


@dataclass(frozen=True, eq=False, kw_only=True)
class RecordingBounds:
    """Measurement intervals of one recording and the assumptions a tracker makes about it.

    The bounds are one :class:`~robots.assumptions.Assumptions` (checked
    there, once): give it as ``assumptions=`` or give its fields by the names
    below, which also read it back.

    Parameters
    ----------
    q_meas : ndarray, shape (K, n)
        Encoder samples, joint units; the true joints at ``t_k = k t_s`` lie in
        ``q_meas[k] +- eps_q``.
    m0 : int
        Initial assembly mode, +1 or -1 (``KinematicModel.mode`` convention).
    assumptions : Assumptions, optional
        The bounds (with a calibration box); else built from the fields:
    t_s : float
        Sampling period, s.
    eps_q : ndarray, shape (n,)
        Encoder error bounds, joint units (a number stands for ``n`` equal bounds).
    a_max : ndarray, shape (n,)
        Componentwise bound on ``|x''|``, pose units per s^2 (a number: ``n`` equal bounds).
    xi_lo, xi_hi : ndarray, shape (m,)
        Calibration box of the geometry, SI.
    v0_max : ndarray, shape (n,), optional
        Bound on ``|x'(0)|``, pose units per s (the tracker's initial velocity box; the assumptions' ``xd0``);
        none if ``None``.
    v_max : ndarray, shape (n,), optional
        Bound on ``|x'(t)|``, pose units per s; none if ``None``.
    x_lo, x_hi : ndarray, shape (n,), optional
        Box the pose stays in, SI; none if ``None``.

    Raises
    ------
    InputError
        On wrong shapes, a bound its rule refuses, no calibration box, an empty box or ``m0`` not +-1.
    """

    q_meas: np.ndarray
    m0: int
    assumptions: Assumptions | None = None
    x_lo: np.ndarray | None = None
    x_hi: np.ndarray | None = None
    t_s: InitVar[float] = UNSET
    eps_q: InitVar[np.ndarray] = UNSET
    a_max: InitVar[np.ndarray] = UNSET
    xi_lo: InitVar[np.ndarray] = UNSET
    xi_hi: InitVar[np.ndarray] = UNSET
    v0_max: InitVar[np.ndarray | None] = UNSET
    v_max: InitVar[np.ndarray | None] = UNSET

    def __post_init__(self, *assumed) -> None:
        set_ = object.__setattr__  # frozen: normalise once
        try:
            q = np.array(self.q_meas, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError("q_meas must be a numeric (K, n) array") from exc
        if q.ndim != 2 or q.shape[0] < 2 or q.shape[1] < 1 or not np.all(np.isfinite(q)):
            raise InputError(f"q_meas must be a finite (K, n) array with K >= 2, got shape {q.shape}")
        n = q.shape[1]
        q.setflags(write=False)
        set_(self, "q_meas", q)
        given = {_ASSUMED[k]: v for k, v in zip(_ASSUMED, assumed)}
        a = held(self.assumptions, given, n=n)
        if a.n != n or a.xi_box is None:
            raise InputError(f"a recording of {n} joints needs assumptions of {n} coordinates with a calibration "
                             f"box, got {a.n} coordinates{'' if a.xi_box is not None else ' and no box'}")
        set_(self, "assumptions", a)
        if self.m0 not in (1, -1):
            raise InputError(f"m0 must be +1 or -1, got {self.m0!r}")
        set_(self, "m0", int(self.m0))
        if (self.x_lo is None) != (self.x_hi is None):
            raise InputError("give both x_lo and x_hi, or neither")
        if self.x_lo is not None:
            xl = V.vector("x_lo", self.x_lo, n, broadcast=True)
            xh = V.vector("x_hi", self.x_hi, n, broadcast=True)
            if np.any(xl >= xh):
                raise InputError(f"need x_lo < x_hi, got {xl.tolist()}, {xh.tolist()}")
            set_(self, "x_lo", xl)
            set_(self, "x_hi", xh)

    @classmethod
    def for_model(cls, kin: KinematicModel, q_meas, t_s: float | None = None, m0: int = 1,
                  **overrides) -> RecordingBounds:
        """The robot's defaults (``t_s``, ``eps_q``, ``a_max``, calibration box,
        ``xd0`` as ``v0_max``, ``x_bounds``), with keyword overrides (``None`` ignored).

        Parameters
        ----------
        kin : KinematicModel
        q_meas : array_like, shape (K, n)
            Encoder samples, rad.
        t_s : float, optional
            Sampling period, s (default ``robot.t_s``).
        m0 : int
            Initial assembly mode, +1 or -1.
        **overrides
            Any other field of :class:`RecordingBounds`.

        Returns
        -------
        RecordingBounds

        Raises
        ------
        InputError
            If ``kin`` is not a KinematicModel, the shapes do not match the robot,
            or a bound is invalid.
        """
        if not isinstance(kin, KinematicModel):
            raise InputError(f"kin must be a KinematicModel, got {type(kin).__name__}")
        r = kin.robot
        given = {k: v for k, v in overrides.items() if v is not None}
        own = {k: given.pop(k) for k in ("x_lo", "x_hi") if k in given}
        if "assumptions" not in given:
            box = (given.pop("xi_lo", r.xi_lo_array), given.pop("xi_hi", r.xi_hi_array))
            assumed = {_ASSUMED[k]: v for k, v in given.items()}
            # the fields by their Assumptions names (v0_max is xd0 there), held in one value: no InitVar repeats them
            given = {"assumptions": Assumptions.for_robot(r, t_s=t_s, xi_box=box, **assumed)}
        out = cls(q_meas=q_meas, m0=m0, x_lo=own.get("x_lo", r.x_lo_array), x_hi=own.get("x_hi", r.x_hi_array),
                  **given)
        if out.q_meas.shape[1] != kin.n or out.xi_lo.shape != (kin.m,):
            raise InputError(f"q_meas must have {kin.n} columns and the box {kin.m} parameters")
        return out

    @property
    def n_samples(self) -> int:
        """Number of samples K."""
        return int(self.q_meas.shape[0])


for _name, _field in _ASSUMED.items():  # after @dataclass: the names read the held assumptions
    setattr(RecordingBounds, _name, reader(_field, none_if_inf=_name in ("v0_max", "v_max")))
del _name, _field


# ------------------------------------------------------------------ motion
def integrate_states(x0, v0, u, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample poses and velocities, each (K, n), of the piecewise quadratic from ``x0, v0`` (n,) and ``u`` (K-1, n).

    ``x_k+1 = x_k + t_s v_k + t_s^2/2 u_k`` and ``v_k+1 = v_k + t_s u_k``, in
    float64, one step after the other: the definition of the motion that
    :func:`~planner.refute.verify_bounce` checks.
    """
    K = u.shape[0] + 1
    x = np.empty((K, u.shape[1]))
    v = np.empty_like(x)
    x[0], v[0] = x0, v0
    for k in range(K - 1):
        x[k + 1] = x[k] + t_s * v[k] + 0.5 * t_s * t_s * u[k]
        v[k + 1] = v[k] + t_s * u[k]
    return x, v


@dataclass(frozen=True, eq=False)
class Counterexample:
    """A candidate bounce or crossing: one geometry and a piecewise-quadratic pose with its joints.

    Attributes
    ----------
    xi : ndarray (m,)
        Geometry, SI.
    x, v : ndarray (K, n)
        Pose (m) and velocity (m/s) at the samples.
    u : ndarray (K - 1, n)
        Constant acceleration on ``[t_k, t_k+1]``, m/s^2.
    q : ndarray (K, n)
        Joints at the samples, rad.
    t_s : float
        Sampling period, s.
    m0 : int
        The initial assembly mode (kept throughout by a bounce, left by a crossing).
    kind : CounterexampleKind
        What the candidate claims about the modes (default: a bounce).
    """

    xi: np.ndarray
    x: np.ndarray
    v: np.ndarray
    u: np.ndarray
    q: np.ndarray
    t_s: float
    m0: int
    kind: CounterexampleKind = CounterexampleKind.BOUNCE

    def __post_init__(self) -> None:
        for nm in ("xi", "x", "v", "u", "q"):
            a = np.array(getattr(self, nm), dtype=float)  # own copy, read-only
            a.setflags(write=False)
            object.__setattr__(self, nm, a)
        try:
            object.__setattr__(self, "kind", CounterexampleKind(self.kind))
        except ValueError:
            raise InputError(f"kind must be one of {[k.value for k in CounterexampleKind]}, got {self.kind!r}") from None

    def trajectory(self, t) -> np.ndarray:
        """Pose ``x(t)`` (m), shape ``(len(t), n)``, of the piecewise quadratic re-integrated
        from ``x[0], v[0]`` and ``u`` (the definition :func:`~planner.refute.verify_bounce` checks);
        ``t`` in ``[0, (K - 1) t_s]`` s."""
        xs, vs = integrate_states(self.x[0], self.v[0], self.u, self.t_s)
        t = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.clip(np.floor(t / self.t_s).astype(int), 0, self.u.shape[0] - 1)
        tau = (t - k * self.t_s)[:, None]
        return xs[k] + tau * vs[k] + 0.5 * tau**2 * self.u[k]
