"""Window reasoning: the whole recording as one constraint network, contracted
forward and backward in time, split on the final assembly mode.

The tracker (:mod:`verifier.step`) is a forward filter: the boxes of sample
``k`` use the readings up to ``k`` only.  A verdict given at the end of a
recording may use every reading.  :func:`track_window` does so:

1. **Tubes per geometry hypothesis.**  The calibration box is partitioned as
   the tracker does (``settings.xi_splits``); each sub-box ``p`` gets its own
   pose and velocity tubes ``[x]_k^p``, ``[xd]_k^p``, ``k = 0..K-1``.  The true
   geometry is one constant vector, so it lies in one sub-box for the whole
   recording: a sub-box refuted in any pass is refuted for good.
2. **Hypotheses on the final mode.**  For ``m`` in {+1, -1}: "the true pose at
   the last sample is in assembly mode ``m``".  Under it, the last pose lies
   in the hull of the forward-kinematics solutions of the last reading whose
   mode is ``m`` or undecided.
3. **Passes.**  A forward pass is the tracker with every sample's boxes
   intersected with the tubes (``verifier.step.advance(prior=...)``); a
   backward pass is the tracker on the time-reversed recording (readings
   ``q_{K-1-k}``, velocity ``-xd``, the same acceleration and reading-error
   bounds, which are symmetric in time), started from the final box of the
   hypothesis and intersected with the tubes.  Passes alternate, backward
   first, until the tubes stop shrinking or a hypothesis is refuted.
4. **Refutation.**  A sub-box whose tubes become empty is refuted; so is one
   whose boxes certify, at the last sample, a mode other than ``m`` (or, at
   the first, other than the initial one).  A hypothesis with every sub-box
   refuted is refuted.  The verdict is certified when exactly one hypothesis
   survives; both refuted means an assumption was violated (``inconsistent``).
5.  **One motion, one geometry.**  When a hypothesis' budget of sub-boxes is
    spent, each of its rows is tested as one constant geometry and one motion
    over the samples around its widest pose box (:mod:`verifier.one_motion`,
    a linear relaxation whose infeasibility is proved by a Farkas certificate);
    the rows proved impossible are dropped, which frees budget for halving,
    and the others' sub-boxes narrowed to the geometries the relaxation
    allows (proved bounds by weak duality); a step that changed something
    earns another round of passes with the narrowed sub-boxes.
6.  **Early stop when no sound method can decide.**  With an
    :class:`Explainer` (the planner's counterexample searches), a hypothesis
    that spent its budget of sub-boxes is offered to it before the one-motion
    step: when it answers :attr:`Explanation.EXPLAINED` (a verified
    admissible motion ending in that mode explains every reading) the
    hypothesis runs no more rounds, and once every hypothesis asked about is
    explained the window stops with ``unknown``
    (:attr:`VerdictReason.UNDECIDABLE`).  Stopping only ever gives
    ``unknown``; a wrong explainer can turn a verdict into ``unknown`` and
    nothing else.

Every pass only removes what cannot hold under the tracker's assumptions and
the hypothesis, so a refuted hypothesis is false (docs/soundness.md, "Window
reasoning").  Shapes: ``K`` samples, pose dimension ``n``; SI units.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Protocol

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError

from . import interval as I
from .linalg import point_inverse
from .motion_model import contract_tubes
from .one_motion import ONE_MOTION_SAMPLES, one_motion_rows
from .settings import TrackerSettings, Verdict
from .step import Backend, advance, configure, init_state, partition_xi, pose_solution_arrays, reading_box
from .tracker import Tracker, initial_box_from_mode, verdict_of

__all__ = ["Reasoning", "HypothesisStatus", "Refutation", "HypothesisResult", "WindowResult", "track_window",
           "FixedLagWindow", "LagResult", "WINDOW_MAX_PASSES", "WINDOW_MAX_GEOMETRIES", "VerdictReason",
           "Explanation", "ExplainRequest", "Explainer"]

#: Default pass budget of a round (backward and forward passes alternate).
WINDOW_MAX_PASSES = 6
#: Default budget of geometry sub-boxes per hypothesis (halving surviving ones between rounds).
WINDOW_MAX_GEOMETRIES = 64
#: Passes stop once the summed tube widths shrink by less than this fraction in a pass.
WINDOW_REL_TOL = 0.02
#: Resolution (m) of the forward-kinematics enumeration of :class:`FixedLagWindow` (once per sample
#: and hypothesis: coarser than the whole-recording passes' 1e-5 m, which splits the locus finely).
_LAG_FK_TOL = 1e-4
#: Rows (hypothesis, geometry sub-box) per kernel call of :class:`FixedLagWindow`: small, so that the
#: rows left once the answer is settled are not run (the first call holds one row of each hypothesis).
_LAG_BATCH = 2
#: A one-motion step that narrows some sub-box by this fraction of a parameter's width (or drops a row) earns
#: the hypothesis another round of passes without halving, up to :data:`ONE_MOTION_ROUNDS` times.
ONE_MOTION_SHRINK = 0.1
#: Rounds of passes a hypothesis may run after one-motion steps when its budget of sub-boxes is spent.
ONE_MOTION_ROUNDS = 6
#: Velocity widths above this (m/s) count as this much when measuring progress (unbounded tubes).
_WIDTH_CAP = 1e3


class Reasoning(str, Enum):
    """How a recording's verdict is reached."""

    FORWARD = "forward"  #: the tracker alone: each box from the readings up to its sample
    WINDOW = "window"  #: the tracker, then window passes over the whole recording when it is not decided

    def __str__(self) -> str:
        return self.value


class HypothesisStatus(str, Enum):
    """What the window passes concluded about one final-mode hypothesis."""

    REFUTED = "refuted"  #: no admissible motion ends in this mode
    CONSISTENT = "consistent"  #: not refuted within the pass budget
    #: not refuted, and an admissible motion ending in this mode explains every reading (the
    #: :class:`Explainer`'s verified witness): no sound method can refute it
    EXPLAINED = "explained"

    def __str__(self) -> str:
        return self.value


class Refutation(str, Enum):
    """Why a hypothesis was refuted."""

    NONE = "none"  #: not refuted
    NO_SOLUTION = "no-solution"  #: the last reading has no pose of this mode for any surviving geometry
    EMPTY_TUBE = "empty-tube"  #: every geometry's tubes became empty
    OTHER_MODE = "other-mode"  #: every surviving geometry certifies another mode at an end of the recording
    FORWARD = "forward"  #: the forward tracker alone certified the other final mode
    ONE_MOTION = "one-motion"  #: no single geometry and motion within a_max explains the last rows' tubes

    def __str__(self) -> str:
        return self.value


class VerdictReason(str, Enum):
    """Why a window gave its verdict (:attr:`WindowResult.reason`)."""

    CERTIFIED = "certified"  #: one final mode refuted (by the window passes or the forward pass), not both
    INCONSISTENT = "inconsistent"  #: every final mode refuted, or the forward pass emptied: an assumption is violated
    NO_INITIAL_MODE = "no-initial-mode"  #: the initial mode is not certified: no hypothesis was tested
    BUDGET = "budget-spent"  #: no hypothesis asked about refuted within the rounds run (more work might decide)
    #: every hypothesis asked about is explained by a verified admissible motion: no sound method can
    #: decide, the window stopped early with ``unknown``
    UNDECIDABLE = "undecidable"

    def __str__(self) -> str:
        return self.value


class Explanation(str, Enum):
    """An :class:`Explainer`'s answer about one final-mode hypothesis."""

    #: a motion satisfying every assumption of the window's settings, ending in this mode, explains every
    #: reading, and the explainer's independent check accepted it
    EXPLAINED = "explained"
    NOT_FOUND = "not-found"  #: no such motion found (which proves nothing)
    NOT_SEARCHED = "not-searched"  #: the explainer did not search (e.g. the problem is beyond its size limit)
    #: the settings assume something the explainer's witness is not checked against (it makes no claim)
    NOT_COVERED = "not-covered"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True, eq=False)
class ExplainRequest:
    """What a window asks an :class:`Explainer` about one final-mode hypothesis (SI units).

    Attributes
    ----------
    model : verifier.model.IntervalModel
    q : ndarray, shape (K, n)
        The readings, rad (or m for a prismatic joint), every ``settings.t_s`` seconds.
    settings : TrackerSettings
        The window's assumptions; a witness must satisfy every one of them.
    xi_box : (lo, hi)
        The window's calibration box ``(m,)`` (``track_window(xi_box=...)`` or the model's).
    x0 : (lo, hi) or None
        The initial pose box ``(n,)`` the window was given (the pose at the
        first sample lies in it); ``None`` when it was given the initial mode.
    initial_mode, final_mode : int
        +1 / -1: the witness starts in ``initial_mode`` and ends in ``final_mode``.
    xi_lo, xi_hi : ndarray, shape (R, m)
        The hypothesis' surviving geometry sub-boxes (seeds for a search; they
        do not restrict the witness, which may use any geometry of ``xi_box``).
    x_lo, x_hi : ndarray, shape (K, n)
        Hull of the hypothesis' pose tubes, m (seeds; no restriction either).
    """

    model: object
    q: np.ndarray
    settings: TrackerSettings
    xi_box: tuple
    x0: tuple | None
    initial_mode: int
    final_mode: int
    xi_lo: np.ndarray
    xi_hi: np.ndarray
    x_lo: np.ndarray
    x_hi: np.ndarray


class Explainer(Protocol):
    """A strategy asked whether a final-mode hypothesis is explained by an admissible motion.

    It must answer :attr:`Explanation.EXPLAINED` only for a motion it has
    checked against every assumption of ``request.settings`` (reading error,
    acceleration, speed bounds, calibration box ``request.xi_box``, initial box
    ``request.x0``, workspace box) and the modes asked; anything it cannot
    check gives :attr:`Explanation.NOT_COVERED`.  The window trusts the answer
    only to stop working on a hypothesis, so a wrong ``EXPLAINED`` can cost a
    verdict (``unknown`` instead) but never give a wrong one.  Implemented by
    :class:`planner.refute.RefutingExplainer` (the verifier imports no planner).
    """

    def __call__(self, request: ExplainRequest) -> Explanation: ...


@dataclass(frozen=True)
class HypothesisResult:
    """One final-mode hypothesis after the window passes.

    Attributes
    ----------
    final_mode : int
        +1 or -1.
    status : HypothesisStatus
    refutation : Refutation
    passes : int
        Passes run under this hypothesis (0: decided by the forward pass).
    geometries_alive : int
        Geometry sub-boxes still consistent at the end.
    complete : bool
        True when a consistent hypothesis ran every round its budget allows.
        False when the rounds stopped early because the other hypothesis was
        refuted (or the forward pass decided): more passes might have refuted
        this one too, and the recording would then be ``inconsistent``.
        True for a refuted hypothesis.
    x_lo, x_hi, xd_lo, xd_hi : ndarray, shape (K, n), or None
        Hull over this hypothesis' surviving geometries of its pose (m) and
        velocity (m/s) tubes; ``None`` when refuted.
    xi_lo, xi_hi : ndarray, shape (geometries_alive, m), or None
        The surviving geometry sub-boxes (units of the robot's ``xi``), as
        contracted by the passes; under this hypothesis one of them holds the
        true geometry.  ``None`` when refuted.
    """

    final_mode: int
    status: HypothesisStatus
    refutation: Refutation
    passes: int
    geometries_alive: int
    complete: bool = True
    x_lo: np.ndarray | None = field(default=None, repr=False, compare=False)
    x_hi: np.ndarray | None = field(default=None, repr=False, compare=False)
    xd_lo: np.ndarray | None = field(default=None, repr=False, compare=False)
    xd_hi: np.ndarray | None = field(default=None, repr=False, compare=False)
    xi_lo: np.ndarray | None = field(default=None, repr=False, compare=False)
    xi_hi: np.ndarray | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True, eq=False)
class WindowResult:
    """Verdict of a recording from the window passes.

    Attributes
    ----------
    verdict : Verdict
    initial_mode : int
        Certified mode at the first sample (0: not certified; then ``unknown``).
    forward_verdict : Verdict
        What the forward tracker alone concluded (the first pass).
    hypotheses : tuple of HypothesisResult
        One per final mode tested.
    x_lo, x_hi, xd_lo, xd_hi : ndarray, shape (K, n)
        Hull, over the surviving hypotheses and geometries, of the contracted
        pose (m) and velocity (m/s) tubes (NaN where none survives).
    max_width_pose, max_width_velocity : float
        Largest side of those tubes over the recording, m and m/s.
    steps : int
    elapsed_s : float
    reason : VerdictReason
        Why the verdict is what it is (``UNDECIDABLE``: stopped early, no
        sound method can decide; ``BUDGET``: undecided within the rounds run).
    """

    verdict: Verdict
    initial_mode: int
    forward_verdict: Verdict
    hypotheses: tuple
    x_lo: np.ndarray = field(repr=False)
    x_hi: np.ndarray = field(repr=False)
    xd_lo: np.ndarray = field(repr=False)
    xd_hi: np.ndarray = field(repr=False)
    max_width_pose: float
    max_width_velocity: float
    steps: int
    elapsed_s: float
    reason: VerdictReason = VerdictReason.CERTIFIED

    def summary(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "verdict": self.verdict.value,
            "reason": self.reason.value,
            "initial_mode": int(self.initial_mode),
            "forward_verdict": self.forward_verdict.value,
            "hypotheses": [
                {"final_mode": h.final_mode, "status": h.status.value, "refutation": h.refutation.value,
                 "passes": h.passes, "geometries_alive": h.geometries_alive, "complete": h.complete}
                for h in self.hypotheses
            ],
            "max_width_pose_m": float(self.max_width_pose),
            "max_width_velocity_mps": float(self.max_width_velocity),
            "steps": int(self.steps),
            "elapsed_s": float(self.elapsed_s),
        }


def _reverse(x, xd):
    """Tubes ``(R, K, 2, n)`` of a motion, as tubes of the time-reversed motion (velocity negated)."""
    xr = x[:, ::-1]
    xdr = -xd[:, ::-1, ::-1]  # [-hi, -lo]: negation is exact
    return np.ascontiguousarray(xr), np.ascontiguousarray(xdr)


def _run(config, q, x0, xi_rows, prior):
    """One pass over readings ``q`` ``(K, n)`` for rows ``R``: tubes ``(R, K, 2, n)``, modes ``(R, K)``, death
    ``(R,)`` and the rows' calibration sub-boxes ``(lo, hi)`` ``(R, m)`` at the end of the pass (contracted by
    every sample's loop closure when ``config`` keeps them, ``keep_xi``; meaningless for a dead row)."""
    lo, hi = xi_rows
    R, (K, n) = lo.shape[0], q.shape
    st = init_state(config, x0, batch=R, xi_box=(lo, hi))
    rec = (np.empty((R, K, 2, n)), np.empty((R, K, 2, n)), np.empty((R, K), np.int64), np.empty((R, K, n)))
    advance(config, st, np.broadcast_to(q, (R, K, n)), rec, prior)
    return rec[0], rec[1], rec[2], st.bad_at.copy(), (st.xi[:, 0].copy(), st.xi[:, 1].copy())


def _hull(x, xd):
    """Hull over the rows of tubes ``(R, K, 2, n)``: ``x_lo, x_hi, xd_lo, xd_hi`` ``(K, n)``."""
    return x[:, :, 0].min(0), x[:, :, 1].max(0), xd[:, :, 0].min(0), xd[:, :, 1].max(0)


def _width(x, xd):
    w = np.minimum(x[..., 1, :] - x[..., 0, :], _WIDTH_CAP).sum() + np.minimum(xd[..., 1, :] - xd[..., 0, :],
                                                                                 _WIDTH_CAP).sum()
    return float(w)


def _search_box(model, search):
    """The box known to hold the last pose: ``search`` or the robot's ``x_bounds``."""
    if search is None:
        search = model.robot.x_bounds
    return np.asarray(search[0], dtype=np.float64), np.asarray(search[1], dtype=np.float64)


def _solutions(model, q_last, s, xi_row, backend, search, tol):
    """Pose solutions of the last reading ``q_last`` (rad, widened by ``eps_q``) for the geometry sub-box
    ``xi_row`` inside ``search``: boxes ``(N, 2, n)`` (m) and their modes ``(N,)`` (0: undecided), or
    ``None`` when the enumeration gave up.  One enumeration serves both final-mode hypotheses."""
    return pose_solution_arrays(model, reading_box(q_last, s.eps_q), xi_row, search, tol=tol, backend=backend)


def _hull_of_mode(sols, mode, search):
    """Hull ``(2, n)`` of the solution boxes of mode ``mode`` or undecided; ``None`` when there is none;
    the search box when the solutions were not isolated (``sols`` is ``None``)."""
    if sols is None:
        return np.stack(search)
    boxes, modes = sols
    # undecided boxes stay: a pose on the singular locus is the limit of both modes
    mine = boxes[(modes == mode) | (modes == 0)]
    if not len(mine):
        return None
    return np.stack([mine[:, 0].min(0), mine[:, 1].max(0)])


def _final_box(model, q_last, mode, s, xi_row, backend, search=None, tol=1e-5):
    """Hull ``(2, n)`` of the pose solutions of the last reading in mode ``mode`` or undecided, inside
    ``search`` (the robot's ``x_bounds`` by default; any box known to hold the pose), ``None`` when there
    is none (the geometry cannot end in that mode), the search box when they could not be isolated."""
    search = _search_box(model, search)
    return _hull_of_mode(_solutions(model, q_last, s, xi_row, backend, search, tol), mode, search)


class _FinalBoxes:
    """Final boxes of geometry sub-boxes, enumerated once per sub-box and shared by both hypotheses
    (they start from the same sub-boxes, and a halved sub-box is often alive under both)."""

    def __init__(self, model, q_last, s, backend):
        self.model, self.q_last, self.s, self.backend = model, q_last, s, backend
        self.search = _search_box(model, None)
        self.cache = {}

    def of(self, xlo, xhi, mode):
        """Final boxes ``(R, 2, n)`` of the rows ``xlo, xhi`` ``(R, m)`` under ``mode``, and which rows have one."""
        boxes, ok = [], np.zeros(len(xlo), dtype=bool)
        for i, (lo, hi) in enumerate(zip(xlo, xhi)):
            key = lo.tobytes() + hi.tobytes()
            if key not in self.cache:
                self.cache[key] = _solutions(self.model, self.q_last, self.s, (lo, hi), self.backend, self.search,
                                             1e-5)
            box = _hull_of_mode(self.cache[key], mode, self.search)
            if box is not None:
                ok[i] = True
                boxes.append(box)
        return (np.stack(boxes) if boxes else np.empty((0, 2, self.model.n))), ok


def _combined_mode(modes, alive):
    """Mode common to every live row, 0 if they differ or none lives."""
    live = modes[alive]
    if live.size == 0 or not np.all(live == live[0]):
        return 0
    return int(live[0])


def track_window(model, q_meas, settings: TrackerSettings, *, x0=None, initial_mode=None, xi_box=None,
                 max_passes: int = WINDOW_MAX_PASSES, rel_tol: float = WINDOW_REL_TOL,
                 max_geometries: int = WINDOW_MAX_GEOMETRIES, backend: str | Backend = Backend.COMPILED,
                 parallel: bool = True, goal: Verdict | None = None,
                 one_motion: int = ONE_MOTION_SAMPLES, explainer: Explainer | None = None) -> WindowResult:
    """Verdict of a whole recording by forward-backward window passes (module docstring).

    Parameters
    ----------
    model : verifier.model.IntervalModel
    q_meas : array_like, shape (K, n)
        Encoder readings, rad, every ``settings.t_s`` seconds.
    settings : TrackerSettings
        The tracker's assumptions and settings (``xi_splits`` gives the geometry sub-boxes).
    x0 : (lo, hi), optional
        Initial pose box ``(n,)``, m.
    initial_mode : {+1, -1}, optional
        Known mode at the first sample (the initial box is then its interval
        forward kinematics).  Give exactly one of ``x0`` and ``initial_mode``.
    xi_box : (lo, hi), optional
        Calibration box ``(m,)``, the robot's by default.
    max_passes : int
        Pass budget per hypothesis after the first forward pass.
    rel_tol : float
        End a round of passes once a pass shrinks the tubes by less than this fraction.
    max_geometries : int
        Budget of geometry sub-boxes per hypothesis: after a round that
        neither refutes nor confirms, the surviving sub-boxes are halved
        while their number stays within it (``settings.xi_splits``' count
        or less: no halving).
    backend : {"compiled", "numpy"}
    parallel : bool
        Compiled backend: geometry sub-boxes in parallel.
    goal : Verdict, optional
        The one verdict the caller asks about (``MODE_CHANGED``: a crossing to
        certify; ``MODE_UNCHANGED``: a bounce).  Only the hypothesis whose
        refutation gives it runs window passes; the other is left consistent
        and incomplete, so any other answer comes out ``unknown`` (or from the
        forward pass).  When the recording is what the caller expects, the
        verdict is the one ``None`` gives, at a fraction of the cost: the true
        hypothesis is never refuted, and its rounds are the costly ones.
        ``None``: both hypotheses.
    one_motion : int
        Samples of the one-motion step (:mod:`verifier.one_motion`): once the budget of sub-boxes is
        spent, after each round, a row is dropped when no single geometry of its sub-box and single
        motion within ``a_max`` in its tubes explain the readings over this many samples around its
        widest pose box (proved by a Farkas certificate), and the others' sub-boxes are narrowed to
        proved bounds of the geometries that can; a step that dropped or narrowed (by
        :data:`ONE_MOTION_SHRINK`) earns another round without halving, up to :data:`ONE_MOTION_ROUNDS`.
        0: not tried.
    explainer : Explainer, optional
        Asked about each hypothesis (of ``goal``'s, when given) once it has
        spent its budget of sub-boxes, before its one-motion step; an
        explained hypothesis runs no more rounds, and when every hypothesis
        asked about is explained the window stops: ``unknown``, reason
        :attr:`VerdictReason.UNDECIDABLE`.  ``None``: never asked (the
        passes, verdict and tubes do not depend on it otherwise).

    Returns
    -------
    WindowResult
    """
    t0 = time.perf_counter()
    s = settings.validated(model.n)
    q = np.ascontiguousarray(np.asarray(q_meas, dtype=np.float64))
    n = model.n
    if q.ndim != 2 or q.shape[1] != n or q.shape[0] < 1:
        raise InputError(f"q_meas must have shape (K, {n}) with K >= 1, got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise InputError("q_meas must be finite")
    if isinstance(max_passes, bool) or int(max_passes) != max_passes or max_passes < 0:
        raise InputError(f"max_passes must be a non-negative integer, got {max_passes!r}")
    if explainer is not None and not callable(explainer):
        raise InputError(f"explainer must be callable (an Explainer) or None, got {type(explainer).__name__}")
    if isinstance(max_geometries, bool) or int(max_geometries) != max_geometries or max_geometries < 1:
        raise InputError(f"max_geometries must be a positive integer, got {max_geometries!r}")
    if not (0.0 <= rel_tol < 1.0):
        raise InputError(f"rel_tol must be in [0, 1), got {rel_tol!r}")
    one_motion = V.count("one_motion", one_motion)
    goal = _goal(goal)
    if (x0 is None) == (initial_mode is None):
        raise InputError("give exactly one of x0 and initial_mode")
    K = q.shape[0]
    XI = model.xi_box() if xi_box is None else tuple(np.asarray(v, dtype=np.float64) for v in xi_box)
    sub_lo, sub_hi = partition_xi((XI[0][None, :], XI[1][None, :]), s.xi_splits)
    xi_rows = (np.ascontiguousarray(sub_lo[0]), np.ascontiguousarray(sub_hi[0]))
    P = xi_rows[0].shape[0]
    if x0 is None:
        x0 = initial_box_from_mode(model, q[0], initial_mode, s, xi_box=XI, backend=str(Backend(backend)))
    x0 = tuple(np.broadcast_to(np.asarray(v, dtype=np.float64), (P, n)).copy() for v in x0)
    flat = replace(s, xi_splits=None)
    cfg_f = configure(model, flat, backend, parallel=parallel)
    # the window's passes carry each row's calibration sub-box from sample to sample (keep_xi), and the
    # rows keep it from pass to pass: the true geometry satisfies every sample's loop closure
    cfg_wf = configure(model, replace(flat, keep_xi=True), backend, parallel=parallel)
    cfg_b = configure(model, replace(flat, xd0=None, keep_xi=True), backend, parallel=parallel)  # final velocity: from the tubes

    fx, fxd, fmode, fbad, fxi = _run(cfg_f, q, x0, xi_rows, None)
    # the rows' sub-boxes after the tracker (contracted only when the settings keep them, keep_xi)
    xi_rows = (np.maximum(xi_rows[0], fxi[0]), np.minimum(xi_rows[1], fxi[1]))
    f_alive = fbad < 0
    m0 = _combined_mode(fmode[:, 0], f_alive)
    mf = _combined_mode(fmode[:, K - 1], f_alive)
    forward_verdict = verdict_of(m0, mf, not f_alive.any())
    tubes, results = [], []
    if forward_verdict is Verdict.INCONSISTENT or m0 == 0:
        results = ()
        verdict = forward_verdict
        reason = VerdictReason.INCONSISTENT if verdict is Verdict.INCONSISTENT else VerdictReason.NO_INITIAL_MODE
        tubes = [(fx[f_alive], fxd[f_alive])]
    elif mf != 0:
        # the forward pass decided: the other final mode is refuted by its certified boxes
        results = (HypothesisResult(mf, HypothesisStatus.CONSISTENT, Refutation.NONE, 0, int(f_alive.sum()), False,
                                    *_hull(fx[f_alive], fxd[f_alive]), xi_rows[0][f_alive], xi_rows[1][f_alive]),
                   HypothesisResult(-mf, HypothesisStatus.REFUTED, Refutation.FORWARD, 0, 0))
        verdict, reason = forward_verdict, VerdictReason.CERTIFIED
        tubes = [(fx[f_alive], fxd[f_alive])]
    else:
        finals = _FinalBoxes(model, q[K - 1], s, str(Backend(backend)))
        keep = np.nonzero(f_alive)[0]
        hyps = [_Hypothesis(finals, xi_rows[0][keep], xi_rows[1][keep], fx[keep], fxd[keep], m0, m)
                for m in (m0, -m0)]
        if not any(h.refuted for h in hyps):
            full_w = XI[1] - XI[0]  # halving measures widths against the calibration box
            ask = None
            if explainer is not None:
                x0_given = None if initial_mode is not None else (x0[0][0].copy(), x0[1][0].copy())

                def ask(h):
                    return explainer(ExplainRequest(model, q, s, XI, x0_given, m0, h.m, h.xlo.copy(), h.xhi.copy(),
                                                    *(a.copy() for a in _hull(h.tx, h.txd)[:2])))
            _decide(hyps, _Passes(q, cfg_wf, cfg_b), max_passes, rel_tol, max_geometries, full_w,
                    _targets(hyps, m0, goal), int(one_motion), ask)
        else:  # refuted by the last reading alone: the other ran no pass
            for h in hyps:
                h.complete = h.refuted
        results = tuple(h.result() for h in hyps)
        tubes = [(h.tx, h.txd) for h in hyps if not h.refuted]
        alive = [h.final_mode for h in results if h.status is not HypothesisStatus.REFUTED]
        if not alive:
            verdict, reason = Verdict.INCONSISTENT, VerdictReason.INCONSISTENT
        elif len(alive) == 2:
            verdict = Verdict.UNKNOWN
            asked = _targets(hyps, m0, goal)
            # the early stop: every hypothesis asked about explained (a wrong claim only costs a verdict)
            undecidable = all(h.explained for h in asked)
            reason = VerdictReason.UNDECIDABLE if undecidable else VerdictReason.BUDGET
        else:
            verdict = Verdict.MODE_UNCHANGED if alive[0] == m0 else Verdict.MODE_CHANGED
            reason = VerdictReason.CERTIFIED
    tubes = [t for t in tubes if len(t[0])]
    if tubes:
        x_lo, x_hi, xd_lo, xd_hi = _hull(np.concatenate([t[0] for t in tubes]), np.concatenate([t[1] for t in tubes]))
    else:
        x_lo, x_hi, xd_lo, xd_hi = (np.full((K, n), np.nan) for _ in range(4))
    with np.errstate(invalid="ignore"):
        wx = float(np.nanmax(x_hi - x_lo)) if tubes else 0.0
        wv = float(np.nanmax(xd_hi - xd_lo)) if tubes else 0.0
    return WindowResult(verdict=verdict, initial_mode=m0, forward_verdict=forward_verdict, hypotheses=results,
                        x_lo=x_lo, x_hi=x_hi, xd_lo=xd_lo, xd_hi=xd_hi, max_width_pose=wx, max_width_velocity=wv,
                        steps=K, elapsed_s=time.perf_counter() - t0, reason=reason)


def _pose_spread(model, x, q, xi_lo, xi_hi):
    """How wide each parameter's width alone makes the pose, per geometry sub-box: ``(R, m)``, m.

    For row ``r`` and parameter ``i``: ``|C| w(f(x_r, q_r, xi_i))`` summed over the pose coordinates, ``f``
    the loop closure evaluated at the midpoint of the pose box ``x`` ``(R, 2, n)`` and of the sub-box except
    parameter ``i``, which keeps its width, with the reading ``q`` (``(n,)``, or ``(R, n)``: one per row), and
    ``C`` the inverse of ``J_x`` there (the first-order pose error of that parameter's uncertainty).  A
    heuristic for where to split: it decides no box.  Every operation is elementwise over the rows, so a
    row's result does not depend on the rows evaluated with it.
    """
    R, m = xi_lo.shape
    n = model.n
    xm = np.repeat(I.midpoint(x[:, 0], x[:, 1]), m, axis=0)
    qm = np.repeat(np.broadcast_to(np.asarray(q, dtype=np.float64), (R, n)), m, axis=0)
    mid = I.midpoint(xi_lo, xi_hi)
    lo, hi = np.repeat(mid, m, axis=0), np.repeat(mid, m, axis=0)
    one = np.tile(np.eye(m, dtype=bool), (R, 1))
    lo[one], hi[one] = xi_lo.reshape(-1), xi_hi.reshape(-1)
    F = model.tape_f.evaluate([(xm, xm), (qm, qm), (lo, hi)])[0]
    J = model.tape_jx.evaluate([(xm, xm), (qm, qm), (np.repeat(mid, m, axis=0),) * 2])[0]
    C = point_inverse(I.midpoint(*J))
    w = (F[1] - F[0]).reshape(R * m, n)
    return np.einsum("rij,rj->r", np.abs(C), w).reshape(R, m)


def _bisect(xi_lo, xi_hi, full_w, spread=None):
    """Halve each geometry sub-box ``(R, m)`` along the parameter whose width spreads the pose most
    (``spread`` ``(R, m)``, :func:`_pose_spread`), or, where that is not finite or not given, the one widest
    relative to the calibration box (widths ``full_w`` ``(m,)``); the two halves share the float split
    point, so they cover the parent."""
    rel = np.where(full_w > 0, (xi_hi - xi_lo) / np.where(full_w > 0, full_w, 1.0), 0.0)
    if spread is not None:
        ok = np.all(np.isfinite(spread), axis=1) & np.any(spread > 0, axis=1)
        rel = np.where(ok[:, None] & (xi_hi > xi_lo), np.where(np.isfinite(spread), spread, 0.0), rel)
    axis = np.argmax(rel, axis=1)
    rows = np.arange(len(axis))
    mid = 0.5 * (xi_lo[rows, axis] + xi_hi[rows, axis])
    left_hi = xi_hi.copy()
    left_hi[rows, axis] = mid
    right_lo = xi_lo.copy()
    right_lo[rows, axis] = mid
    return np.concatenate([xi_lo, right_lo]), np.concatenate([left_hi, xi_hi])


class _Hypothesis:
    """The rows (geometry sub-boxes with their tubes) under "the last pose is in mode ``m``".

    A row is dropped once its tubes become empty or certify another mode at
    an end of the recording; the hypothesis is refuted when no row is left.
    """

    def __init__(self, finals, xlo, xhi, tx, txd, m0, m):
        self.finals, self.m0, self.m = finals, m0, m
        self.xlo, self.xhi, self.tx, self.txd = xlo, xhi, tx, txd
        self.passes = 0
        self.refutation = Refutation.NONE
        self.complete = True  # False once the rounds stopped before this hypothesis used its budget
        self.extra = 0  # rounds run after one-motion steps without halving (ONE_MOTION_ROUNDS)
        self.asked = False  # offered to the explainer (once, when its budget of sub-boxes is spent)
        self.explained = False  # the explainer answered EXPLAINED: no more rounds
        self.kept = set()  # sub-boxes (bytes of lo, hi) a one-motion step left as they were
        self._final_boxes()

    @property
    def refuted(self) -> bool:
        return self.refutation is not Refutation.NONE

    def _keep(self, live):
        self.xlo, self.xhi, self.tx, self.txd = self.xlo[live], self.xhi[live], self.tx[live], self.txd[live]
        self.final = self.final[live]

    def _final_boxes(self):
        self.final, ok = self.finals.of(self.xlo, self.xhi, self.m)
        self.xlo, self.xhi, self.tx, self.txd = self.xlo[ok], self.xhi[ok], self.tx[ok], self.txd[ok]
        if not ok.any():
            self.refutation = Refutation.NO_SOLUTION if self.passes == 0 else Refutation.EMPTY_TUBE

    def starts(self, backward):
        """Initial boxes ``(R, n)`` of a pass: the final box within the tube's last box (backward), or the
        tube's first box (forward)."""
        if backward:
            end = self.tx[:, -1]
            return np.maximum(self.final[:, 0], end[:, 0]), np.minimum(self.final[:, 1], end[:, 1])
        return self.tx[:, 0, 0], self.tx[:, 0, 1]

    def take(self, x, xd, md, bad, xi):
        """The tubes and contracted calibration sub-boxes ``xi`` (``(lo, hi)`` ``(R, m)``) of a pass over this
        hypothesis' rows (forward time); drop the rows it refutes."""
        self.passes += 1
        last, first = md[:, -1], md[:, 0]
        other = ((last != 0) & (last != self.m)) | ((first != 0) & (first != self.m0))
        s = self.finals.s
        # empty tubes, or tubes no motion within a_max fits (contracted between samples: step 8)
        dead = (bad >= 0) | contract_tubes(x, xd, s.t_s, s.a_max, compiled=self.finals.backend == Backend.COMPILED)
        live = ~dead & ~other
        self.tx, self.txd = x, xd
        # the pass started from these sub-boxes and only contracted them; intersecting is exact and keeps
        # a row's sub-box inside its parent's whatever the kernel holds
        self.xlo, self.xhi = np.maximum(self.xlo, xi[0]), np.minimum(self.xhi, xi[1])
        live &= np.all(self.xlo <= self.xhi, axis=1)  # no geometry of the sub-box fits every sample
        if not live.any():
            self.refutation = Refutation.EMPTY_TUBE if np.all(dead) else Refutation.OTHER_MODE
        self._keep(live)

    def one_motion(self, q, samples) -> bool:
        """Drop the rows that no single geometry of their sub-box and single motion in their tubes explain
        over ``samples`` samples of the readings ``q``, and narrow the others' sub-boxes to the geometries
        that can (:func:`verifier.one_motion.one_motion_rows`).  True when a row was dropped or a sub-box
        narrowed by at least :data:`ONE_MOTION_SHRINK` along some parameter (another round may then decide
        more).  A row whose sub-box a step left as it was is not asked again while its sub-box stays the same
        (only its tubes changed, by the passes it already survived): on certify's plans 148 such rows asked
        again were never dropped and one was narrowed, by under a tenth; a row not asked is only kept, which
        is always sound (docs/tracker.md)."""
        keys = [lo.tobytes() + hi.tobytes() for lo, hi in zip(self.xlo, self.xhi)]
        ask = np.array([k not in self.kept for k in keys], dtype=bool)
        out, lo, hi = np.zeros(len(keys), dtype=bool), self.xlo.copy(), self.xhi.copy()
        if ask.any():
            out[ask], lo[ask], hi[ask] = one_motion_rows(self.finals.model, self.finals.s, q,
                                                         (self.xlo[ask], self.xhi[ask]), self.tx[ask], self.txd[ask],
                                                         samples, compiled=self.finals.backend == Backend.COMPILED)
        same = ask & ~out & np.all(lo == self.xlo, axis=1) & np.all(hi == self.xhi, axis=1)
        self.kept.update(k for k, s in zip(keys, same) if s)
        w0 = self.xhi - self.xlo
        # the proved bounds only narrow: intersecting is exact and keeps each sub-box inside its own
        self.xlo, self.xhi = np.maximum(self.xlo, lo), np.minimum(self.xhi, hi)
        live = ~out & np.all(self.xlo <= self.xhi, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            narrowed = np.any((self.xhi - self.xlo) < (1.0 - ONE_MOTION_SHRINK) * w0, axis=1)
        changed = bool(np.any(~live) or np.any(narrowed[live]))
        if not live.any():
            self.refutation = Refutation.ONE_MOTION
        self._keep(live)
        return changed

    def split(self, full_w, q_first):
        """Halve every surviving geometry sub-box along the parameter that spreads the pose most at the two
        ends of the recording (first reading ``q_first``); children start from their parent's tubes."""
        model = self.finals.model
        R, n = len(self.xlo), model.n
        # both ends in one evaluation of the tapes (their numpy cost is per call, not per row)
        q_ends = np.concatenate([np.broadcast_to(np.asarray(q_first, dtype=np.float64), (R, n)),
                                 np.broadcast_to(np.asarray(self.finals.q_last, dtype=np.float64), (R, n))])
        with I.quiet_fp():
            both = _pose_spread(model, np.concatenate([self.tx[:, 0], self.tx[:, -1]]), q_ends,
                                np.concatenate([self.xlo, self.xlo]), np.concatenate([self.xhi, self.xhi]))
            spread = both[:R] + both[R:]
        self.xlo, self.xhi = _bisect(self.xlo, self.xhi, full_w, spread)
        self.tx, self.txd = np.concatenate([self.tx, self.tx]), np.concatenate([self.txd, self.txd])
        self._final_boxes()

    def result(self) -> HypothesisResult:
        if self.refuted:
            return HypothesisResult(self.m, HypothesisStatus.REFUTED, self.refutation, self.passes, 0)
        status = HypothesisStatus.EXPLAINED if self.explained else HypothesisStatus.CONSISTENT
        return HypothesisResult(self.m, status, self.refutation, self.passes, len(self.xlo),
                                self.complete, *_hull(self.tx, self.txd), self.xlo, self.xhi)


class _Passes:
    """The passes of the window: one ``advance`` call per pass over a hypothesis' rows, spread over the
    threads (each row is its own scenario: the rows batched with it change none of its boxes)."""

    def __init__(self, q, cfg_f, cfg_b):
        self.q, self.cfg_f, self.cfg_b = q, cfg_f, cfg_b
        self.q_rev = np.ascontiguousarray(q[::-1])
        self.rows = 0  # rows run by every pass so far: the cost :func:`_decide` balances

    def run(self, h, backward):
        """One pass over the rows of hypothesis ``h``, which takes its tubes."""
        x0, xi = h.starts(backward), (h.xlo, h.xhi)
        self.rows += len(h.xlo)
        if backward:
            x, xd, md, bad, xi = _run(self.cfg_b, self.q_rev, x0, xi, _reverse(h.tx, h.txd))
            x, xd = _reverse(x, xd)
            md = md[:, ::-1]
        else:
            x, xd, md, bad, xi = _run(self.cfg_f, self.q, x0, xi, (h.tx, h.txd))
        h.take(x, xd, md, bad, xi)


def _round(h, passes, max_passes, rel_tol):
    """One round of ``h``: backward and forward passes alternate until one shrinks its tubes by less than
    ``rel_tol`` (after at least two), ``max_passes``, or the hypothesis is refuted."""
    if h.refuted:  # no row left since its last halving
        return
    width = _width(h.tx, h.txd)
    for p in range(1, max_passes + 1):
        passes.run(h, backward=bool(p % 2))
        if h.refuted:
            return
        new = _width(h.tx, h.txd)
        if p >= 2 and not new < (1.0 - rel_tol) * width:
            return
        width = new


#: The verdicts a window can be asked about (``track_window(goal=...)``).
_GOALS = (Verdict.MODE_CHANGED, Verdict.MODE_UNCHANGED)


def _goal(goal):
    """``goal`` as a :class:`Verdict` of :data:`_GOALS`, or ``None``."""
    if goal is None:
        return None
    try:
        verdict = Verdict(goal)
    except ValueError:
        verdict = None
    if verdict not in _GOALS:
        raise InputError(f"goal must be one of {[g.value for g in _GOALS]} or None, got {goal!r}")
    return verdict


def _targets(hyps, m0, goal):
    """The hypotheses whose refutation can give the verdict ``goal`` (all of them when ``goal`` is ``None``):
    ``MODE_CHANGED`` is reached only by refuting the initial mode ``m0``, ``MODE_UNCHANGED`` only by refuting
    the other one."""
    if goal is None:
        return list(hyps)
    return [h for h in hyps if (h.m == m0) == (goal is Verdict.MODE_CHANGED)]


def _decide(hyps, passes, max_passes, rel_tol, max_geometries, full_w, targets=None, one_motion=0, ask=None):
    """Rounds on the hypotheses ``targets`` (all of ``hyps`` by default), halving each one's geometries
    after each of its rounds while they stay within ``max_geometries``, until a hypothesis is refuted or
    none can be halved.

    The next round goes to the hypothesis that has run the fewest rows so far (the initial mode's first).
    Under valid assumptions the true hypothesis is never refuted, and each hypothesis' rounds do not
    depend on the other's: the verdict does not depend on this order, while the cost does.  A false
    hypothesis loses rows at every round; the true one keeps them all and costs the most.  Balancing the
    rows run bounds the work by about twice what the false hypothesis needs to be refuted (up to one
    round of the other), where taking the hypotheses level by level spends the true one's rounds at
    every level.

    The rounds stop at the first refutation: the other hypothesis is then left as it stands, consistent
    but marked incomplete (``HypothesisResult.complete``), since its skipped rounds might have refuted
    it too (the recording would then be ``inconsistent``).  Running them would cost the surviving
    hypothesis' rounds on every decided recording, and a refuted hypothesis is false whatever the
    other one's tubes are (measured: benchmarks/README.md [8]).  A hypothesis left out of ``targets``
    runs no round and is marked incomplete too.

    ``ask`` (``ask(h) -> Explanation``, optional) is called once per hypothesis, when its budget of
    sub-boxes is spent and before its one-motion step (so a recording decided within the budget never
    calls it).  An explained hypothesis leaves the rounds (complete: no sound pass can refute a
    hypothesis an admissible motion satisfies); once every hypothesis of ``targets`` is explained the
    rounds stop.  Trusting a wrong answer only keeps a false hypothesis alive: ``unknown``, never a
    wrong verdict.
    """
    open_ = list(hyps if targets is None else targets)
    for h in hyps:
        if h not in open_:
            h.complete = h.refuted
    rows = [0] * len(open_)
    while open_:
        i = min(range(len(open_)), key=rows.__getitem__)  # ties: the first, the initial mode's
        h = open_[i]
        before = passes.rows
        _round(h, passes, max_passes, rel_tol)
        rows[i] += passes.rows - before
        if ask is not None and not h.refuted and not h.asked and 2 * len(h.xlo) > max_geometries:
            h.asked = True
            h.explained = Explanation(ask(h)) is Explanation.EXPLAINED
            if h.explained:
                del open_[i], rows[i]
                if all(t.explained for t in (hyps if targets is None else targets)):
                    return  # no sound method can decide: stop (unknown)
                continue
        if one_motion and not h.refuted and 2 * len(h.xlo) > max_geometries:
            # the budget is spent: the one-motion step is the last resort; the rows it drops give the halving
            # room again, and the sub-boxes it narrows tighten the next round's tubes
            changed = h.one_motion(passes.q, one_motion)
            if changed and not h.refuted and 2 * len(h.xlo) > max_geometries and h.extra < ONE_MOTION_ROUNDS:
                h.extra += 1
                continue  # another round with the narrowed sub-boxes, no halving
        if not h.refuted and 2 * len(h.xlo) <= max_geometries:
            h.split(full_w, passes.q[0])  # may refute it: no child has a final box
        elif not h.refuted:
            del open_[i], rows[i]  # its budget is spent: it stays consistent and complete
            continue
        if h.refuted:
            for other in open_:
                other.complete = other.refuted
            return


@dataclass(frozen=True)
class LagResult:
    """What a :class:`FixedLagWindow` knows after reading sample ``k``.

    Attributes
    ----------
    k : int
        Index of the reading just fed.
    mode_now : int
        Mode certified at sample ``k`` (+1 / -1, 0 not certified): the
        tracker's, or the one left when the other final-mode hypothesis over
        the last ``lag + 1`` samples is refuted.
    lagged : int
        Index ``k - lag`` of the sample whose mode ``lagged_mode`` is (-1
        before ``lag`` samples were read).
    lagged_mode : int
        Mode certified at sample ``k - lag`` from the readings up to ``k``.
    consistent : bool
        False once every geometry hypothesis of the tracker became empty.
    """

    k: int
    mode_now: int
    lagged: int
    lagged_mode: int
    consistent: bool


class FixedLagWindow:
    """Window reasoning online, with a fixed lag: the mode of sample ``k`` certified from the readings up to ``k + lag``.

    After each reading the forward tracker advances; when its mode at the
    newest sample ``k`` or at ``k - lag`` is not certified, one backward pass
    per final-mode hypothesis ("the pose at ``k`` is in mode ``m``") runs over
    the last ``lag + 1`` samples, from the hull of that mode's
    forward-kinematics solutions intersected with the tracker's box at ``k``
    and inside the tracker's boxes (:func:`track_window`'s backward pass on a
    window ending at ``k``).  A hypothesis whose geometry sub-boxes all die is
    refuted: the mode at ``k`` is the other one.  The mode at ``k - lag`` is
    the one every surviving sub-box of every surviving hypothesis certifies.
    Rows (hypothesis, sub-box) run a pair at a time, and those that can no
    longer change either answer are skipped (:meth:`_window`); the forward
    kinematics of the newest reading is enumerated once per sub-box.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    settings : TrackerSettings
    x0 : (lo, hi)
        Initial pose box ``(n,)``, m.
    lag : int
        Samples of look-ahead (>= 1).
    xi_box : (lo, hi), optional
    backend : {"compiled", "numpy"}
    parallel : bool
        Compiled backend: the rows of a window call over the thread slots (the
        pair of each call, one per hypothesis, runs on two cores; the same
        answers).
    """

    def __init__(self, model, settings: TrackerSettings, x0, *, lag: int, xi_box=None,
                 backend: str | Backend = Backend.COMPILED, parallel: bool = True):
        if isinstance(lag, bool) or int(lag) != lag or lag < 1:
            raise InputError(f"lag must be a positive number of samples, got {lag!r}")
        self.model, self.lag, self.backend = model, int(lag), str(Backend(backend))
        s = settings.validated(model.n)
        self.settings = s
        self.tracker = Tracker(model, settings, x0, xi_box=xi_box, backend=backend)
        XI = model.xi_box() if xi_box is None else tuple(np.asarray(v, dtype=np.float64) for v in xi_box)
        lo, hi = partition_xi((XI[0][None, :], XI[1][None, :]), s.xi_splits)
        self.xi_rows = (np.ascontiguousarray(lo[0]), np.ascontiguousarray(hi[0]))
        # keep_xi: within a window the sub-box is contracted by each sample's loop closure in turn
        self.cfg_b = configure(model, replace(s, xi_splits=None, xd0=None, keep_xi=True), backend,
                               parallel=parallel)
        L, n = self.lag + 1, model.n
        # the last L samples newest first, the order of the backward pass: readings (rad), the tracker's
        # pose boxes (m) and its velocity boxes of the reversed motion ([-hi, -lo], m/s), its modes
        self._q = np.zeros((L, n))
        self._x = np.zeros((L, 2, n))
        self._xd_rev = np.zeros((L, 2, n))
        self._mode = np.zeros(L, np.int64)

    def update(self, q) -> LagResult:
        """Feed the reading ``q`` ``(n,)``, rad."""
        r = self.tracker.update(q)
        k = r.k
        for buf in (self._q, self._x, self._xd_rev, self._mode):
            buf[1:] = buf[:-1]  # one slot older (numpy copies overlapping ranges correctly)
        self._q[0] = np.asarray(q, dtype=np.float64)
        self._x[0] = r.x
        self._xd_rev[0, 0], self._xd_rev[0, 1] = -r.xd[1], -r.xd[0]  # negation is exact
        self._mode[0] = r.mode
        j = k - self.lag
        if not r.consistent:
            return LagResult(k, 0, j if j >= 0 else -1, 0, False)
        if j < 0:
            return LagResult(k, r.mode, -1, 0, True)
        lagged_fwd = int(self._mode[-1])
        if r.mode != 0 and lagged_fwd != 0:
            return LagResult(k, r.mode, j, lagged_fwd, True)
        alive_modes, lagged_modes = self._window(need_now=r.mode == 0, need_lagged=lagged_fwd == 0)
        mode_now = r.mode if r.mode != 0 or len(alive_modes) != 1 else alive_modes[0]
        lagged = lagged_fwd
        if lagged == 0 and lagged_modes and all(v == lagged_modes[0] for v in lagged_modes):
            lagged = int(lagged_modes[0])
        return LagResult(k, int(mode_now), j, int(lagged), True)

    def _window(self, need_now: bool, need_lagged: bool):
        """Backward passes over the window, a few (hypothesis, geometry sub-box) rows per ``advance`` call,
        only while a row can still change the answer: the final modes not refuted (``need_now``: the
        tracker's mode at ``k`` is open) and the modes the surviving rows certify at ``k - lag``
        (``need_lagged``).

        A hypothesis is alive once one of its rows survives, and the lagged mode stays open once a surviving
        row certifies none or two disagree; rows that cannot change either are never run.  The answer is
        therefore the one all the rows give.  Returns the alive modes and the surviving rows' lagged modes.
        """
        search = (self._x[0, 0], self._x[0, 1])
        P = self.xi_rows[0].shape[0]
        sols = {}
        alive, lagged_modes = [], []

        def useful(m):
            open_lag = need_lagged and not (0 in lagged_modes or len(set(lagged_modes)) > 1)
            return (need_now and m not in alive) or open_lag

        # rows interleaved by hypothesis, so that the first call can show both alive
        todo = [(m, p) for p in range(P) for m in (1, -1)]
        while todo:
            batch, rest = [], []
            for m, p in todo:
                if not useful(m):
                    continue
                if len(batch) == _LAG_BATCH:
                    rest.append((m, p))
                    continue
                if p not in sols:  # one enumeration of the newest reading's poses serves both hypotheses
                    sols[p] = _solutions(self.model, self._q[0], self.settings,
                                         (self.xi_rows[0][p], self.xi_rows[1][p]), self.backend, search, _LAG_FK_TOL)
                box = _hull_of_mode(sols[p], m, search)
                if box is not None:
                    batch.append((m, p, np.maximum(box[0], search[0]), np.minimum(box[1], search[1])))
            todo = rest
            if not batch:
                continue
            hyp = np.array([b[0] for b in batch])
            rows = np.array([b[1] for b in batch])
            shape = (len(batch),) + self._x.shape
            prior = (np.broadcast_to(self._x, shape), np.broadcast_to(self._xd_rev, shape))
            _, _, md, bad, _ = _run(self.cfg_b, self._q, (np.stack([b[2] for b in batch]), np.stack([b[3] for b in batch])),
                                 (self.xi_rows[0][rows], self.xi_rows[1][rows]), prior)
            live = (bad < 0) & ~((md[:, 0] != 0) & (md[:, 0] != hyp))
            for m in (1, -1):
                if m not in alive and np.any(live & (hyp == m)):
                    alive.append(m)
            lagged_modes.extend(md[live, -1].tolist())
        return alive, lagged_modes
