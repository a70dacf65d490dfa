"""The tracker's mutable state, and its schema: the one definition both backends read.

:class:`TrackerState` holds everything a run changes.  Its array fields fall
in two parts, marked on each field: the *row* arrays (one entry per geometry
hypothesis of each scenario) and the *scenario* arrays.  The compiled kernels
receive the two parts as named tuples built from these marks
(:data:`ROW_FIELDS`, :data:`SCENARIO_FIELDS`; ``verifier.compiled.step.Rows``
and ``Scenarios``), so a field added here reaches them under the same name.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

__all__ = ["TrackerState", "ROW_FIELDS", "SCENARIO_FIELDS"]

_ROWS = {"part": "rows"}
_SCENARIOS = {"part": "scenarios"}


@dataclass(eq=False)
class TrackerState:
    """Everything a run changes, for ``B`` scenarios of ``P`` geometry hypotheses.

    Row arrays (``R = B P`` rows): ``x``, ``xd`` ``(R, 2, n)`` pose (m) and
    velocity (m/s) boxes, row 0 lower and row 1 upper bounds; ``xi``
    ``(R, 2, m)`` calibration sub-box; ``q`` ``(R, 2, n)`` joint box of the
    last sample, rad; ``past_x``, ``past_q`` ``(R, D, 2, n)`` and ``past_r``
    ``(R, D, n)``: boxes and readings of the last ``D`` samples (slot
    ``k mod D``); ``row_bad`` ``(R,)`` sample at which the hypothesis became
    empty (-1: consistent).

    Scenario arrays (``B``): ``init_mode``, ``mode`` (certified mode at the
    first / last sample, 0 = not certified), ``streak`` (sample since which
    ``mode`` holds), ``bad_at`` (first sample with no consistent hypothesis,
    -1 none), ``max_width_pose``, ``max_width_velocity`` (m, m/s), ``x_hull``,
    ``xd_hull`` ``(B, 2, n)`` the boxes of the last sample, ``qdd_hull``
    ``(B, n)`` the joint-acceleration bound used (rad/s^2, ``inf`` none).
    ``k`` counts the samples consumed.
    """

    batch: int
    hypotheses: int
    k: int
    x: np.ndarray = field(metadata=_ROWS)
    xd: np.ndarray = field(metadata=_ROWS)
    xi: np.ndarray = field(metadata=_ROWS)
    q: np.ndarray = field(metadata=_ROWS)
    past_x: np.ndarray = field(metadata=_ROWS)
    past_q: np.ndarray = field(metadata=_ROWS)
    past_r: np.ndarray = field(metadata=_ROWS)
    row_bad: np.ndarray = field(metadata=_ROWS)
    init_mode: np.ndarray = field(metadata=_SCENARIOS)
    mode: np.ndarray = field(metadata=_SCENARIOS)
    streak: np.ndarray = field(metadata=_SCENARIOS)
    bad_at: np.ndarray = field(metadata=_SCENARIOS)
    max_width_pose: np.ndarray = field(metadata=_SCENARIOS)
    max_width_velocity: np.ndarray = field(metadata=_SCENARIOS)
    x_hull: np.ndarray = field(metadata=_SCENARIOS)
    xd_hull: np.ndarray = field(metadata=_SCENARIOS)
    qdd_hull: np.ndarray = field(metadata=_SCENARIOS)
    #: the compiled implementation's per-thread scratch and argument tuples, built once per state
    kernel_args: dict = field(default_factory=dict, repr=False)


def _part(name: str) -> tuple[str, ...]:
    return tuple(f.name for f in fields(TrackerState) if f.metadata.get("part") == name)


#: The row arrays of :class:`TrackerState`, in order (the compiled kernels' ``Rows``).
ROW_FIELDS = _part("rows")
#: The scenario arrays of :class:`TrackerState`, in order (the compiled kernels' ``Scenarios``).
SCENARIO_FIELDS = _part("scenarios")
