"""Named phases of the long calls, for a progress display or none.

A long call (``certify_crossing``, a check with window passes) says which
phase it is in and how many units the phase has, then counts units done.
The display is the caller's: the command line draws one bar per phase with
its elapsed time (``planner.cli.setup.PhaseBar``); a script may pass any
object with the two methods of :class:`Progress`, or a plain callable, which
only counts (the calls' older per-sample ``progress(k)`` form).
"""

from __future__ import annotations

from enum import Enum
from typing import Protocol, runtime_checkable

__all__ = ["Phase", "Progress", "enter", "suffixed"]


class Phase(str, Enum):
    """The phases a display names (its text is what is shown)."""

    FORWARD = "forward pass"
    WINDOW = "window passes"
    SEARCH = "speed search"
    MONTE_CARLO = "Monte Carlo"
    REFUTATION = "counterexample searches"
    BOUNCE = "bounce search"

    def __str__(self) -> str:
        return self.value


@runtime_checkable
class Progress(Protocol):
    """What a phase-aware display provides."""

    def phase(self, name: str, total: int | None = None, unit: str = "step") -> None:
        """A new phase begins: ``total`` units (None: not known in advance) of ``unit`` (empty: a wait
        that counts nothing)."""

    def __call__(self, done=1) -> None:
        """One more unit of the current phase is done (the argument is ignored)."""


def enter(progress, phase: Phase | str, total: int | None = None, unit: str = "step") -> None:
    """Tell ``progress`` that ``phase`` begins, if it takes phases (``None`` and plain callables do not)."""
    if isinstance(progress, Progress):
        progress.phase(str(phase), total, unit)


class _Suffixed:
    def __init__(self, inner: Progress, suffix: str):
        self._inner, self._suffix = inner, suffix

    def phase(self, name: str, total: int | None = None, unit: str = "step") -> None:
        self._inner.phase(f"{name}{self._suffix}", total, unit)

    def __call__(self, done=1) -> None:
        self._inner(done)


def suffixed(progress, suffix: str):
    """``progress`` with ``suffix`` appended to every phase name (a plain callable or None as is)."""
    return _Suffixed(progress, suffix) if isinstance(progress, Progress) else progress
