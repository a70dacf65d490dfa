"""What a window reports: how a verdict is reached, each final-mode hypothesis' outcome, the window's result;
and what the online monitor reports after each reading (its events and the state of its window)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from ..settings import Verdict
from ..step import Event

__all__ = ["Reasoning", "HypothesisStatus", "Refutation", "VerdictReason", "HypothesisResult", "WindowResult",
           "WindowState", "OnlineEvent", "OnlineResult"]


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


class WindowState(str, Enum):
    """What the anchored window of an :class:`OnlineMonitor` is doing."""

    IDLE = "idle"  #: the tracker certifies the mode at the newest sample (or never did): no window
    OPEN = "open"  #: the mode was lost: the window from the anchor reasons over the readings as they arrive
    GAVE_UP = "gave-up"  #: the window reached the horizon undecided: unknown until the tracker certifies a mode

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class OnlineEvent:
    """A change of what is certified, as an :class:`OnlineMonitor` reports it.

    Attributes
    ----------
    event : Event
        ``MODE_GAINED`` (certified for the first time, or again in the mode it had before it was lost),
        ``MODE_LOST``, ``MODE_CHANGED`` (certified in the other mode than the last certified one) or
        ``INCONSISTENT`` (an assumption was violated).
    k : int
        Sample the event is about: from it on the new mode is certified.
    known_at : int
        Sample at whose reading it became known (``k`` for the tracker's events; later for a window's).
    mode : int
        Certified mode from ``k`` on (+1 / -1; 0 for ``MODE_LOST`` and ``INCONSISTENT``).
    by_window : bool
        Decided by the anchored window over the readings from the anchor to ``k``.
    """

    event: Event
    k: int
    known_at: int
    mode: int
    by_window: bool = False


@dataclass(frozen=True)
class OnlineResult:
    """What an :class:`OnlineMonitor` knows after reading sample ``k``.

    Attributes
    ----------
    k : int
        Index of the reading just fed.
    mode : int
        Mode certified at sample ``k`` (+1 / -1; 0 not certified).
    x, xd : (lo, hi) arrays (n,)
        Pose (m) and velocity (m/s) boxes at sample ``k`` (from the decided mode's boxes once a window decided).
    consistent : bool
        False once every geometry hypothesis became empty (an assumption was violated).
    events : tuple of OnlineEvent
        What changed with this reading, a window's decision about an earlier sample included.
    window : WindowState
    """

    k: int
    mode: int
    x: tuple
    xd: tuple
    consistent: bool
    events: tuple
    window: WindowState
