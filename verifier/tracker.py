"""Sound pose-and-velocity tracking through Type 2 singularities (Algorithm 1).

At every sample ``k`` the tracker holds boxes ``[x]_k`` and ``[xd]_k`` that
contain the true end-effector pose and velocity, for a batch of ``B``
scenarios at once:

1. **prediction** over the sampling interval ``t_s``, from ``|xdd| <= a_max``
   (Taylor with Lagrange remainder, one component at a time)::

       [xd]_{k+1} = [xd]_k + t_s [a]
       [x]_{k+1}  = [x]_k  + t_s [xd]_k + (t_s^2 / 2) [a]

   (Algorithm 1 line 7 as printed adds ``t_s [xd]_k`` with the velocity
   contracted *at* ``t_k`` only, which does not enclose the velocity over the
   interval; the Taylor form does.)
2. **measurement**: ``[q]_{k+1} = q_meas + [-eps_q, eps_q]``; velocity
   information from the joint samples by one of three models
   (:class:`VelocityModel`): the default, sound *displacement* model relates
   ``x_k - x_{k-j}`` to ``q_k - q_{k-j}`` over several baselines ``j`` (its
   truncation error ``(h/2) a_max`` stays in Cartesian space); the
   *joint-fd* model uses the finite difference ``(q_{k+1} - q_k) / t_s`` with
   quantisation ``2 eps_q / t_s`` plus truncation ``(t_s / 2) qdd`` from a
   given or derived joint-acceleration bound (:func:`_qdd_over_step`); the
   *paper* model keeps only the quantisation term (unsound).
3. **contraction** to a fixpoint: HC4Revise and interval Newton on
   ``f(x, q, xi) = 0`` for the pose, Gauss–Seidel on ``J_x xd = -J_q qd`` for
   the velocity; optionally the calibration box ``[xi]`` is kept contracted
   from step to step (the true geometry is constant).
4. **mode**: +1 / -1 when ``mode_sign * det J_x`` has that sign over the whole
   box, else 0.

The calibration box may be partitioned into geometry hypotheses
(``xi_splits``), tracked side by side; a hypothesis whose box becomes empty
is refuted, the reported boxes are the hull of the surviving ones, and a mode
is certified only when every survivor certifies it.  If every hypothesis
becomes empty, some assumption (``a_max``, ``[xi]``, ``eps_q``, the initial
box, the joint-acceleration bound) was violated: the scenario is reported
``inconsistent`` at that step and never given a verdict.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from enum import Enum

import numpy as np

from . import interval as I
from robots.errors import InputError
from .step import Backend, advance, configure, init_state, pose_solutions

__all__ = [
    "Verdict",
    "VelocityModel",
    "TrackerSettings",
    "TrackResult",
    "BatchResult",
    "initial_box_from_mode",
    "verdict_of",
    "track",
    "track_batch",
    "SampleStream",
]


class Verdict(str, Enum):
    """Outcome of a tracked run (a value, never ``None``)."""

    MODE_CHANGED = "mode-changed"
    MODE_UNCHANGED = "mode-unchanged"
    UNKNOWN = "unknown"
    INCONSISTENT = "inconsistent"

    def __str__(self) -> str:
        return self.value


class VelocityModel(str, Enum):
    """How joint samples inform the end-effector velocity."""

    #: Default, sound: displacement over several baselines ``h = j t_s``;
    #: quantisation ``2 eps_q / h`` in joint space, truncation ``(h/2) a_max``
    #: in Cartesian space (see :func:`verifier.contractors.velocity_displacement`).
    SOUND = "sound"
    #: Sound: finite-difference joint velocity ``(q_k - q_{k-1}) / t_s`` with
    #: quantisation ``2 eps_q / t_s`` plus truncation ``(t_s / 2) max|qdd|``, the
    #: joint-acceleration bound given (``qdd_bound``) or derived every step
    #: from the boxes and ``a_max``.
    JOINT_FD = "joint-fd"
    #: The paper's quantisation-only bound ``2 eps_q / t_s``.  NOT sound: the
    #: finite difference's truncation error is ignored (kept to reproduce the
    #: paper's Table II).
    PAPER = "paper"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class TrackerSettings:
    """Bounds and options of the tracker.

    Parameters
    ----------
    t_s : float
        Sampling period, s.
    eps_q : float or array (n,)
        Encoder error bound, rad: ``|q_meas - q_true| <= eps_q``.
    a_max : array (n,)
        End-effector acceleration bound, m/s^2 (componentwise ``|xdd_i| <= a_max_i``).
    v_max : array (n,)
        End-effector velocity bound, m/s (``inf`` = none).
    xd0 : array (n,)
        Initial velocity bound, m/s: ``|xd(0)| <= xd0`` (the paper's 0.1 m/s).
    velocity_model : VelocityModel
        ``SOUND`` (default), ``JOINT_FD`` or ``PAPER`` (quantisation only, unsound).
    baselines : tuple of int
        Sample spans ``j`` used by the ``SOUND`` model (each gives a sound
        enclosure; they are intersected).
    qdd_bound : float or array (n,) or None
        ``JOINT_FD`` only: assumed bound on ``|qdd|``, rad/s^2.  ``None``
        (default) derives a bound at every step from the boxes and ``a_max``;
        a number is an assumption the user vouches for (intersected with the
        derived one).
    eps_q_fast, drift_rate : float or array (n,), optional
        A reading error that drifts slowly (``SOUND`` model only): the error
        ``e_k = q_meas,k - q_true,k`` is, besides ``|e_k| <= eps_q``, the sum
        of a part bounded by ``eps_q_fast`` (rad) and a part that changes by at
        most ``drift_rate`` rad/s, so that a difference over ``j`` samples errs
        by at most ``min(2 eps_q, 2 eps_q_fast + drift_rate j t_s)``.  Both
        ``None`` (default): readings err independently, ``2 eps_q``.  Planning
        uses it for executions whose joints follow the plan up to a slowly
        varying geometry term (``planner.execution``).
    keep_xi : bool
        Keep the calibration box contracted across steps.
    split_boxes : int
        Budget of sub-boxes for branch and prune of an undecided pose box
        (0 disables it).
    split_tol : float
        Pieces narrower than this (m) are not split further.
    split_max_width : float
        Boxes wider than this (m) are not split (a box that wide has lost the
        track; splitting it costs the whole budget every step).
    xi_splits : tuple of int (m,), optional
        Partition the calibration box into ``prod(xi_splits)`` sub-boxes
        (``xi_splits[i]`` equal parts along parameter ``i``) and track each
        geometry hypothesis separately; the true geometry is one constant
        vector, so it lies in one sub-box for the whole run.  A sub-box that
        becomes inconsistent is refuted; the boxes reported are the hull of
        the sub-boxes still consistent, and a mode is certified only when all
        of them certify it.
    max_iter : int
        Maximal fixpoint iterations per step.
    rel_tol : float
        The fixpoint stops when no box width shrinks by more than this fraction.
    """

    t_s: float
    eps_q: float | np.ndarray
    a_max: np.ndarray
    v_max: np.ndarray | None = None
    xd0: np.ndarray | None = None
    velocity_model: VelocityModel = VelocityModel.SOUND
    baselines: tuple = (1, 2, 4, 8, 16)
    qdd_bound: float | np.ndarray | None = None
    eps_q_fast: float | np.ndarray | None = None
    drift_rate: float | np.ndarray | None = None
    keep_xi: bool = False
    split_boxes: int = 64
    split_tol: float = 2e-4
    split_max_width: float = 0.06
    xi_splits: tuple | None = None
    max_iter: int = 6
    rel_tol: float = 0.02

    @classmethod
    def for_robot(cls, robot, **overrides) -> "TrackerSettings":
        """The robot's default bounds (``t_s``, ``eps_q``, ``a_max``, ``xd0``,
        ``xi_splits``), with keyword overrides (``None`` values are ignored)."""
        args = dict(t_s=robot.t_s, eps_q=robot.eps_q, a_max=robot.a_max, xd0=robot.xd0,
                    xi_splits=getattr(robot, "xi_splits", None))
        args.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**args)

    def validated(self, n: int) -> "TrackerSettings":
        """Check values and broadcast vectors to shape ``(n,)``."""

        def vec(v, name, default=None, allow_inf=False):
            if v is None:
                v = default
            a = np.broadcast_to(np.asarray(v, dtype=np.float64), (n,)).copy()
            if np.any(np.isnan(a)) or np.any(a < 0) or (not allow_inf and not np.all(np.isfinite(a))):
                raise InputError(f"{name} must be {'non-negative' if allow_inf else 'finite and non-negative'}, got {v}")
            return a

        if not (np.isfinite(self.t_s) and self.t_s > 0):
            raise InputError(f"sampling period t_s must be positive and finite, got {self.t_s}")
        if int(self.max_iter) < 1:
            raise InputError("max_iter must be at least 1")
        qdd = None if self.qdd_bound is None else vec(self.qdd_bound, "qdd_bound", allow_inf=True)
        splits = None
        if self.xi_splits is not None:
            splits = tuple(int(v) for v in self.xi_splits)
            if any(v < 1 for v in splits):
                raise InputError(f"xi_splits must be positive integers, got {self.xi_splits}")
        if (self.eps_q_fast is None) != (self.drift_rate is None):
            raise InputError("eps_q_fast and drift_rate go together: give both or neither")
        fast = None if self.eps_q_fast is None else vec(self.eps_q_fast, "eps_q_fast")
        rate = None if self.drift_rate is None else vec(self.drift_rate, "drift_rate")
        base = tuple(sorted({int(j) for j in self.baselines}))
        if not base or base[0] < 1:
            raise InputError(f"baselines must be positive sample counts, got {self.baselines}")
        return replace(
            self,
            eps_q=vec(self.eps_q, "eps_q"),
            a_max=vec(self.a_max, "a_max"),
            v_max=vec(self.v_max, "v_max", np.inf, allow_inf=True),
            xd0=vec(self.xd0, "xd0", np.inf, allow_inf=True),
            velocity_model=VelocityModel(self.velocity_model),
            qdd_bound=qdd,
            eps_q_fast=fast,
            drift_rate=rate,
            baselines=base,
            xi_splits=splits,
        )


@dataclass(frozen=True)
class BatchResult:
    """Per-scenario summaries of a batched run (arrays of shape ``(B,)``).

    ``initial_mode``/``final_mode``: certified mode at the first/last sample
    (0 = not certified); ``certified_at_step``: first sample from which the
    final mode stays certified to the end (-1 if none); ``inconsistent_at_step``:
    first sample where a box became empty (-1 if none);
    ``max_width_pose``/``max_width_velocity``: largest box side over the run
    (m, m/s) before any inconsistency.
    """

    verdict: np.ndarray
    initial_mode: np.ndarray
    final_mode: np.ndarray
    certified_at_step: np.ndarray
    inconsistent_at_step: np.ndarray
    max_width_pose: np.ndarray
    max_width_velocity: np.ndarray
    steps: int
    elapsed_s: float


@dataclass(frozen=True)
class TrackResult:
    """One tracked run with its per-step boxes.

    Attributes
    ----------
    verdict : Verdict
    initial_mode, final_mode : int
        Certified modes at the first and last sample (0 = not certified).
    certified_at_step, inconsistent_at_step : int
        See :class:`BatchResult` (-1 = none).
    max_width_pose, max_width_velocity : float
        ``m_x`` (m) and ``m_xd`` (m/s) of the paper's Table II.
    x_lo, x_hi, xd_lo, xd_hi : array (K, n)
        Pose (m) and velocity (m/s) boxes at every sample.
    mode : array (K,)
        Certified mode at every sample.
    qdd_bound : array (K, n)
        Joint-acceleration bound used at every sample, rad/s^2 (``inf`` where none).
    steps : int
    elapsed_s : float
    """

    verdict: Verdict
    initial_mode: int
    final_mode: int
    certified_at_step: int
    inconsistent_at_step: int
    max_width_pose: float
    max_width_velocity: float
    x_lo: np.ndarray
    x_hi: np.ndarray
    xd_lo: np.ndarray
    xd_hi: np.ndarray
    mode: np.ndarray
    qdd_bound: np.ndarray
    steps: int
    elapsed_s: float
    settings: TrackerSettings = field(repr=False, default=None)

    def summary(self) -> dict:
        """JSON-ready summary (SI units)."""
        return {
            "verdict": self.verdict.value,
            "initial_mode": int(self.initial_mode),
            "final_mode": int(self.final_mode),
            "certified_at_step": None if self.certified_at_step < 0 else int(self.certified_at_step),
            "inconsistent_at_step": None if self.inconsistent_at_step < 0 else int(self.inconsistent_at_step),
            "steps": int(self.steps),
            "max_width_pose_m": float(self.max_width_pose),
            "max_width_velocity_mps": float(self.max_width_velocity),
            "elapsed_s": float(self.elapsed_s),
        }


def initial_box_from_mode(model, q0, mode: int, settings: TrackerSettings, xi_box=None, x_search=None,
                          backend: str = "compiled"):
    """Enclosure of the pose in assembly mode ``mode`` for the first sample.

    Encloses every solution of ``f(x, q, xi) = 0`` with ``q in q0 + [eps_q]``,
    ``xi in [xi]``, inside ``x_search`` (the robot's ``x_bounds``), and returns
    the hull of the solution boxes of the requested mode.  ``backend``
    (``"compiled"`` or ``"numpy"``) runs the branch and prune.

    Raises
    ------
    InputError
        If no solution of that mode exists (the mode does not match the data),
        or a solution box's mode cannot be certified (start too close to a
        Type 2 singularity).
    """
    s = settings.validated(model.n)
    q0 = np.asarray(q0, dtype=np.float64)
    Q = I.sub(q0, q0, s.eps_q, s.eps_q)[0], I.add(q0, q0, s.eps_q, s.eps_q)[1]
    XI = model.xi_box() if xi_box is None else xi_box
    if x_search is None:
        lo, hi = model.robot.x_bounds
        x_search = (np.asarray(lo, dtype=float), np.asarray(hi, dtype=float))
    sols = pose_solutions(model, Q, XI, x_search, tol=1e-5, backend=backend)
    if sols is None:
        raise InputError("could not isolate the forward-kinematics solutions of the first sample; give --x0 instead")
    if not sols:
        raise InputError("the first joint sample has no forward-kinematics solution with the calibration box: check the robot and the data")
    if any(m == 0 for _, m in sols):
        raise InputError(
            "the first sample is too close to a Type 2 singularity to certify its assembly mode; give --x0 instead"
        )
    mine = [b for b, m in sols if m == mode]
    if not mine:
        found = sorted({m for _, m in sols})
        raise InputError(
            f"initial mode {mode:+d} does not match the data: the first sample only admits mode(s) {', '.join(f'{m:+d}' for m in found)}"
        )
    lo = np.min([b[0] for b in mine], axis=0)
    hi = np.max([b[1] for b in mine], axis=0)
    return lo, hi


def verdict_of(initial_mode: int, final_mode: int, inconsistent: bool) -> Verdict:
    """The verdict of a run from its certified modes at the first and last sample (0: not certified).

    ``inconsistent`` (a box became empty) overrides everything; a mode not
    certified at either end gives ``unknown``.
    """
    if inconsistent:
        return Verdict.INCONSISTENT
    if initial_mode == 0 or final_mode == 0:
        return Verdict.UNKNOWN
    return Verdict.MODE_UNCHANGED if initial_mode == final_mode else Verdict.MODE_CHANGED


def track_batch(model, q_meas, settings: TrackerSettings, x0, xi_box=None, record: bool = False, progress=None,
                backend: str = "compiled", parallel: bool = True, spread_hypotheses: bool = False):
    """Run the tracker on ``B`` scenarios at once.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    q_meas : array (B, K, n) or SampleStream
        Encoder readings, rad, sampled every ``settings.t_s``; a
        :class:`SampleStream` supplies them one sample at a time, so memory
        stays ``O(B)`` however long the run.
    settings : TrackerSettings
    x0 : (lo, hi)
        Initial pose boxes, arrays ``(B, n)`` or ``(n,)``, m.
    xi_box : (lo, hi), optional
        Calibration box ``(m,)`` or ``(B, m)``; the robot's by default.
    record : bool
        Also return every box (memory ``O(B K n)``).
    progress : callable, optional
        Called as ``progress(k)`` after each sample (after each block of
        samples with the compiled backend).
    backend : {"compiled", "numpy"}
        The compiled kernels (default) or the numpy reference
        (:mod:`verifier.step`).
    parallel, spread_hypotheses : bool
        Compiled backend: spread the scenarios, or the geometry hypotheses of
        each sample, over numba's threads; the same results either way (see
        :class:`verifier.step.StepConfig`).

    Returns
    -------
    BatchResult, and when ``record`` a dict of arrays ``x_lo, x_hi, xd_lo,
    xd_hi`` ``(B, K, n)``, ``mode`` ``(B, K)``, ``qdd_hi`` ``(B, K, n)``.
    """
    t0 = time.perf_counter()
    config = configure(model, settings, backend, parallel=parallel, spread_hypotheses=spread_hypotheses)
    if not isinstance(q_meas, SampleStream):
        q_meas = np.asarray(q_meas, dtype=np.float64)
        if q_meas.ndim != 3 or q_meas.shape[2] != model.n:
            raise InputError(f"q_meas must have shape (B, K, {model.n}), got {q_meas.shape}")
        q_meas = SampleStream.from_array(q_meas)
    B, K, n = q_meas.batch, q_meas.steps, model.n
    state = init_state(config, x0, batch=B, xi_box=xi_box)
    rec = None
    if record:
        rec = {k: np.full((B, K, n), np.nan) for k in ("x_lo", "x_hi", "xd_lo", "xd_hi", "qdd_hi")}
        rec["mode"] = np.zeros((B, K), np.int8)
    chunk = _BLOCK if config.backend is Backend.COMPILED else 1
    for k0 in range(0, K, chunk):
        k1 = min(K, k0 + chunk)
        q = np.stack([np.asarray(q_meas.sample(k), dtype=np.float64).reshape(B, -1) for k in range(k0, k1)], axis=1)
        block = None
        if record:
            block = (np.empty((B, k1 - k0, 2, n)), np.empty((B, k1 - k0, 2, n)), np.empty((B, k1 - k0), np.int64),
                     np.empty((B, k1 - k0, n)))
        advance(config, state, q, block)
        if record:
            rec["x_lo"][:, k0:k1], rec["x_hi"][:, k0:k1] = block[0][:, :, 0], block[0][:, :, 1]
            rec["xd_lo"][:, k0:k1], rec["xd_hi"][:, k0:k1] = block[1][:, :, 0], block[1][:, :, 1]
            rec["mode"][:, k0:k1] = block[2]
            rec["qdd_hi"][:, k0:k1] = block[3]
        if progress is not None:
            for k in range(k0, k1):
                progress(k)
    bad_at = state.bad_at.copy()
    init_mode = state.init_mode.astype(np.int8)
    final = np.where(bad_at < 0, state.mode, 0).astype(np.int8)
    cert = np.where(final != 0, state.streak, -1)
    verdict = np.empty(B, dtype=object)
    for b in range(B):
        verdict[b] = verdict_of(init_mode[b], final[b], bad_at[b] >= 0)
    res = BatchResult(
        verdict=verdict,
        initial_mode=init_mode,
        final_mode=final,
        certified_at_step=cert,
        inconsistent_at_step=bad_at,
        max_width_pose=state.max_width_pose.copy(),
        max_width_velocity=state.max_width_velocity.copy(),
        steps=K,
        elapsed_s=time.perf_counter() - t0,
    )
    return (res, rec) if record else res


#: Samples per kernel call of the compiled backend (progress is reported per block).
_BLOCK = 256


@dataclass(frozen=True)
class SampleStream:
    """Joint samples supplied one at a time: ``sample(k)`` returns ``(B, n)``.

    Parameters
    ----------
    batch : int
        Number of scenarios ``B``.
    steps : int
        Number of samples ``K``.
    sample : callable
        ``sample(k) -> array (B, n)`` of encoder readings at ``t = k t_s``, rad.
    """

    batch: int
    steps: int
    sample: object

    @staticmethod
    def from_array(q):
        """Stream over an array of shape ``(B, K, n)``."""
        q = np.asarray(q, dtype=np.float64)
        return SampleStream(q.shape[0], q.shape[1], lambda k: q[:, k, :])


def track(model, q_meas, settings: TrackerSettings, *, x0=None, initial_mode=None, xi_box=None, progress=None,
          backend: str = "compiled", spread_hypotheses: bool = False) -> TrackResult:
    """Track one recorded joint trajectory and give a verdict.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    q_meas : array (K, n)
        Encoder readings, rad, every ``settings.t_s`` seconds.
    settings : TrackerSettings
    x0 : (lo, hi), optional
        Initial pose box ``(n,)``, m.
    initial_mode : {+1, -1}, optional
        Known assembly mode at the first sample (then the initial box is the
        interval forward-kinematics enclosure of that mode).  Give exactly one
        of ``x0`` and ``initial_mode``.
    xi_box : (lo, hi), optional
        Calibration box, the robot's by default.
    backend : {"compiled", "numpy"}
    spread_hypotheses : bool
        See :func:`track_batch`.

    Returns
    -------
    TrackResult
    """
    t0 = time.perf_counter()
    q_meas = np.asarray(q_meas, dtype=np.float64)
    if q_meas.ndim != 2 or q_meas.shape[1] != model.n:
        raise InputError(f"q_meas must have shape (K, {model.n}), got {q_meas.shape}")
    if len(q_meas) < 2:
        raise InputError("at least two joint samples are needed")
    if not np.all(np.isfinite(q_meas)):
        raise InputError("joint samples must be finite (found NaN or inf)")
    if (x0 is None) == (initial_mode is None):
        raise InputError("give exactly one of an initial pose box (x0) and an initial assembly mode")
    if initial_mode is not None:
        if initial_mode not in (1, -1):
            raise InputError(f"initial mode must be +1 or -1, got {initial_mode}")
        x0 = initial_box_from_mode(model, q_meas[0], initial_mode, settings, xi_box, backend=backend)
    else:
        lo, hi = (np.asarray(v, dtype=np.float64) for v in x0)
        if lo.shape != (model.n,) or hi.shape != (model.n,) or np.any(~(lo <= hi)):
            raise InputError(f"initial pose box must be {model.n} intervals with lo <= hi, got {x0}")
        x0 = (lo, hi)
    res, rec = track_batch(model, q_meas[None], settings, x0, xi_box=xi_box, record=True, progress=progress,
                           backend=backend, spread_hypotheses=spread_hypotheses)
    s = settings.validated(model.n)
    verdict = res.verdict[0]
    if initial_mode is not None and verdict is not Verdict.INCONSISTENT and res.initial_mode[0] != initial_mode:
        # the given mode's box did not certify at step 0 after contraction
        verdict = Verdict.UNKNOWN if res.initial_mode[0] == 0 else verdict
    return TrackResult(
        verdict=verdict,
        initial_mode=int(res.initial_mode[0]),
        final_mode=int(res.final_mode[0]),
        certified_at_step=int(res.certified_at_step[0]),
        inconsistent_at_step=int(res.inconsistent_at_step[0]),
        max_width_pose=float(res.max_width_pose[0]),
        max_width_velocity=float(res.max_width_velocity[0]),
        x_lo=rec["x_lo"][0],
        x_hi=rec["x_hi"][0],
        xd_lo=rec["xd_lo"][0],
        xd_hi=rec["xd_hi"][0],
        mode=rec["mode"][0],
        qdd_bound=rec["qdd_hi"][0],
        steps=res.steps,
        elapsed_s=time.perf_counter() - t0,
        settings=s,
    )
