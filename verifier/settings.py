"""What a tracker run assumes and answers: its settings, its velocity model, its verdict.

Apart from :mod:`verifier.tracker` so that the step (:mod:`verifier.step`) and
the loops over it (:mod:`verifier.tracker`) share them without an import cycle.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

from crosscert.robots.errors import InputError


__all__ = ["Verdict", "VelocityModel", "TrackerSettings"]


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


@dataclass(frozen=True, eq=False)
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
