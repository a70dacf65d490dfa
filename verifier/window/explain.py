"""The window's early stop: the :class:`Explainer` protocol, what it is asked and what it answers."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Protocol

import numpy as np

from ..settings import TrackerSettings

__all__ = ["Explanation", "ExplainRequest", "Explainer"]


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
