"""What a tracker run assumes and answers: its settings, its velocity model, its verdict.

Apart from :mod:`verifier.tracker` so that the step (:mod:`verifier.step`) and
the loops over it (:mod:`verifier.tracker`) share them without an import cycle.
"""

from __future__ import annotations

from dataclasses import InitVar, dataclass
from enum import Enum

import numpy as np

from crosscert.robots.assumptions import UNSET, Assumptions, held, reader
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


#: The tracker's view of its :class:`~robots.assumptions.Assumptions`: these
#: attribute names of :class:`TrackerSettings` read the held value.
ASSUMED = ("t_s", "eps_q", "a_max", "v_max", "xd0", "eps_q_fast", "drift_rate")

@dataclass(frozen=True, eq=False, kw_only=True)
class TrackerSettings:
    """The tracker's assumptions (one :class:`~robots.assumptions.Assumptions`) and its options.

    Built from the assumptions' fields by keyword (``t_s``, ``eps_q``,
    ``a_max``, ``v_max``, ``xd0``, ``eps_q_fast``, ``drift_rate``: see
    :class:`~robots.assumptions.Assumptions` for their units and rules), or
    from a built value (``assumptions=``); those names read the held value
    back as ``(n,)`` arrays (``t_s`` a float; ``v_max``/``xd0`` ``inf`` where
    there is no bound; ``eps_q_fast``/``drift_rate`` ``None`` without a drift
    model).  Everything is checked once, here.

    Parameters
    ----------
    assumptions : Assumptions, optional
        The bounds of the run (else built from the keyword fields).
    velocity_model : VelocityModel
        ``SOUND`` (default), ``JOINT_FD`` or ``PAPER`` (quantisation only, unsound).
    baselines : tuple of int
        Sample spans ``j`` used by the ``SOUND`` model (each gives a sound
        enclosure; they are intersected); stored sorted, without repeats.
    qdd_bound : float or array (n,) or None
        ``JOINT_FD`` only: assumed bound on ``|qdd|``, joint units per s^2.
        ``None`` (default) derives a bound at every step from the boxes and
        ``a_max``; a number is an assumption the user vouches for (intersected
        with the derived one).
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

    assumptions: Assumptions | None = None
    velocity_model: VelocityModel = VelocityModel.SOUND
    baselines: tuple = (1, 2, 4, 8, 16)
    qdd_bound: float | np.ndarray | None = None
    keep_xi: bool = False
    split_boxes: int = 64
    split_tol: float = 2e-4
    split_max_width: float = 0.06
    xi_splits: tuple | None = None
    max_iter: int = 6
    rel_tol: float = 0.02
    t_s: InitVar[float] = UNSET
    eps_q: InitVar[float | np.ndarray] = UNSET
    a_max: InitVar[np.ndarray] = UNSET
    v_max: InitVar[np.ndarray | None] = UNSET
    xd0: InitVar[np.ndarray | None] = UNSET
    eps_q_fast: InitVar[float | np.ndarray | None] = UNSET
    drift_rate: InitVar[float | np.ndarray | None] = UNSET

    def __post_init__(self, *assumed) -> None:
        set_ = object.__setattr__  # frozen: normalise once
        set_(self, "assumptions", held(self.assumptions, dict(zip(ASSUMED, assumed))))
        n = self.assumptions.n
        if int(self.max_iter) < 1:
            raise InputError("max_iter must be at least 1")
        set_(self, "max_iter", int(self.max_iter))
        set_(self, "velocity_model", VelocityModel(self.velocity_model))
        if self.qdd_bound is not None:
            q = np.broadcast_to(np.asarray(self.qdd_bound, dtype=np.float64), (n,)).copy()
            if np.any(np.isnan(q)) or np.any(q < 0):
                raise InputError(f"qdd_bound must be non-negative, got {self.qdd_bound}")
            q.setflags(write=False)
            set_(self, "qdd_bound", q)
        if self.xi_splits is not None:
            splits = tuple(int(v) for v in self.xi_splits)
            if any(v < 1 for v in splits):
                raise InputError(f"xi_splits must be positive integers, got {self.xi_splits}")
            set_(self, "xi_splits", splits)
        base = tuple(sorted({int(j) for j in self.baselines}))
        if not base or base[0] < 1:
            raise InputError(f"baselines must be positive sample counts, got {self.baselines}")
        set_(self, "baselines", base)

    @classmethod
    def for_robot(cls, robot, **overrides) -> "TrackerSettings":
        """The robot's default bounds (``t_s``, ``eps_q``, ``a_max``, ``xd0``) and
        ``xi_splits``, with keyword overrides of assumptions or options (``None`` values are ignored)."""
        given = {k: v for k, v in overrides.items() if v is not None}
        assumed = {k: given.pop(k) for k in ASSUMED if k in given}
        if "assumptions" not in given:
            fast, rate = assumed.pop("eps_q_fast", None), assumed.pop("drift_rate", None)
            drift = None if fast is None and rate is None else (fast, rate)
            given["assumptions"] = Assumptions.for_robot(robot, drift=drift, **assumed)
        given.setdefault("xi_splits", getattr(robot, "xi_splits", None))
        return cls(**given)

    def validated(self, n: int) -> "TrackerSettings":
        """These settings, for a model of ``n`` coordinates (checked at construction: only the dimension here)."""
        if n != self.assumptions.n:
            raise InputError(f"the settings bound {self.assumptions.n} coordinates, the model has {n}")
        return self


for _name in ASSUMED:  # after @dataclass: the InitVar defaults live in __init__, the names read the value
    setattr(TrackerSettings, _name, reader(_name))
del _name
