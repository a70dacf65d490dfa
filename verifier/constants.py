"""The step's constants, packed by name from one schema.

Both implementations of the step (:mod:`verifier.step`: the numpy reference
and the compiled kernels) read the validated settings through this one
:class:`StepConstants` value, by field name: scalars as fields, per-axis
vectors as fields of a record array ``axis`` ``(n,)`` (``axis["eps_q"]`` in
numpy, ``axis[i].eps_q`` in compiled code), the velocity baselines as a
record array ``baseline`` ``(J,)``.  Derived intervals are rounded outward
here, once.  :func:`pack_constants` is the only place of the tracker that
reads the assumptions (``t_s``, ``eps_q``, ``a_max``, ``v_max``, ``xd0``, the
drift model): from the settings' one
:class:`~robots.assumptions.Assumptions` value, their owner.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import interval as I

__all__ = ["AXIS_DTYPE", "BASELINE_DTYPE", "StepConstants", "pack_constants", "for_step", "SOUND", "JOINT_FD", "PAPER",
           "velocity_model_code"]

#: Codes of the velocity models in :attr:`StepConstants.velocity_model`.
SOUND, JOINT_FD, PAPER = range(3)
_VMODEL_CODE = {"sound": SOUND, "joint-fd": JOINT_FD, "paper": PAPER}


def velocity_model_code(name) -> int:
    """The code of the velocity model ``name`` (a :class:`verifier.settings.VelocityModel` or its value)."""
    return _VMODEL_CODE[getattr(name, "value", name)]


#: Per-axis constants (one record per pose / joint coordinate).
AXIS_DTYPE = np.dtype([
    ("eps_q", np.float64),  # reading error bound, rad
    ("a_max", np.float64),  # |xdd| bound, m/s^2
    ("v_max", np.float64),  # |xd| bound, m/s
    ("xd0", np.float64),  # |xd| bound at the first sample, m/s
    ("qdd_bound", np.float64),  # |qdd| bound, rad/s^2 (inf: none given)
    ("half_ts2_a_lo", np.float64), ("half_ts2_a_hi", np.float64),  # (t_s^2 / 2) [-a_max, a_max], m
    ("ts_a_lo", np.float64), ("ts_a_hi", np.float64),  # t_s [-a_max, a_max], m/s
    ("quant_lo", np.float64), ("quant_hi", np.float64),  # [-2 eps_q, 2 eps_q] / t_s, rad/s
])

#: Velocity baselines of the displacement model: ``j`` samples, ``h = j t_s`` (s, outward).
BASELINE_DTYPE = np.dtype([("j", np.int64), ("h_lo", np.float64), ("h_hi", np.float64)])


class StepConstants(NamedTuple):
    """What the step reads besides the boxes, built by :func:`pack_constants`.

    Attributes
    ----------
    t_s : float
        Sampling period, s (the nominal one when the steps differ, :mod:`verifier.clock`).
    step_lo, step_hi : float
        Enclosure of this step ``t_k - t_{k-1}``, s: ``t_s`` twice for a constant period; an
        uneven recording's step (its stamps, their error bound) otherwise.  The fields ``axis``
        (``half_ts2_a``, ``ts_a``, ``quant``), ``baseline`` and ``diff_err`` are derived from the
        same step, :func:`for_step`.
    rel_tol, split_tol, split_max_width : float
        Fixpoint tolerance (relative width gain), split-and-prune piece width
        and largest box side it starts on, m.
    velocity_model : int
        :data:`SOUND`, :data:`JOINT_FD` or :data:`PAPER`.
    max_iter, split_boxes, hypotheses : int
        Contraction rounds, split-and-prune pieces (0: off), geometry hypotheses ``P``.
    keep_xi, has_qdd_bound : bool
    axis : record array (n,) of :data:`AXIS_DTYPE`
    baseline : record array (J,) of :data:`BASELINE_DTYPE`
    diff_err : float64 (J, 2, n)
        Error interval of a difference of two readings ``j`` samples apart, rad (outward).
    depth : int
        Samples kept in the window of past boxes.
    """

    t_s: float
    step_lo: float
    step_hi: float
    rel_tol: float
    split_tol: float
    split_max_width: float
    velocity_model: int
    max_iter: int
    split_boxes: int
    hypotheses: int
    keep_xi: bool
    has_qdd_bound: bool
    axis: np.ndarray
    baseline: np.ndarray
    diff_err: np.ndarray
    depth: int


def _difference_error(a, span: float, two_eps):
    """Error interval of a difference of two readings ``span`` s apart at most, rad (outward)."""
    if a.eps_q_fast is None:
        return two_eps
    two_fast = I.scale(2.0, -a.eps_q_fast, a.eps_q_fast)[1]
    bound = I.add(two_fast, two_fast, *I.mul(span, span, a.drift_rate, a.drift_rate))[1]
    bound = np.minimum(bound, two_eps[1])
    return -bound, bound


def _timed(a, n: int, step, spans):
    """The constants that depend on the time between samples: ``axis`` fields ``half_ts2_a``, ``ts_a`` and
    ``quant`` (per-axis arrays), the baselines' ``h`` ``(J, 2)`` and ``diff_err`` ``(J, 2, n)``, from the step's
    enclosure ``step`` ``(lo, hi)`` and the baselines' ``spans`` ``(J, 2)`` (s, outward, lower bounds > 0)."""
    lo, hi = step
    A = (-a.a_max, a.a_max)
    with I.quiet_fp():
        # t^2/2 and t [a] over every t of the step: largest at its upper end (t > 0)
        half_ts2_A = I.mul(*I.scale(0.5, *I.mul(hi, hi, hi, hi)), *A)
        ts_A = I.scale(hi, *A)
        two_eps = I.scale(2.0, -a.eps_q, a.eps_q)
        quant = I.div(*two_eps, lo, hi)  # 2 eps / t
        diff = np.array([np.stack(_difference_error(a, float(h[1]), two_eps)) for h in spans]).reshape(-1, 2, n)
    return half_ts2_A, ts_A, quant, np.asarray(spans, dtype=np.float64).reshape(-1, 2), diff


def _fill(axis, baseline, half_ts2_A, ts_A, quant, h) -> None:
    for name, v in (("half_ts2_a_lo", half_ts2_A[0]), ("half_ts2_a_hi", half_ts2_A[1]), ("ts_a_lo", ts_A[0]),
                    ("ts_a_hi", ts_A[1]), ("quant_lo", quant[0]), ("quant_hi", quant[1])):
        axis[name] = v
    baseline["h_lo"], baseline["h_hi"] = h[:, 0], h[:, 1]


def pack_constants(s, n: int) -> StepConstants:
    """The constants of validated settings ``s`` (vectors ``(n,)``), rounded outward, for steps of ``t_s``."""
    a = s.assumptions  # t_s, eps_q, a_max, v_max, xd0 and the drift model: their one owner (robots.assumptions)
    ts = a.t_s
    with I.quiet_fp():
        spans = np.array([np.stack(I.mul(float(j), float(j), ts, ts)) for j in s.baselines]).reshape(-1, 2)
    half_ts2_A, ts_A, quant, h, diff = _timed(a, n, (ts, ts), spans)
    axis = np.zeros(n, AXIS_DTYPE)
    for name, v in (("eps_q", a.eps_q), ("a_max", a.a_max), ("v_max", a.v_max), ("xd0", a.xd0),
                    ("qdd_bound", np.inf if s.qdd_bound is None else s.qdd_bound)):
        axis[name] = v
    baseline = np.zeros(len(s.baselines), BASELINE_DTYPE)
    baseline["j"] = s.baselines
    _fill(axis, baseline, half_ts2_A, ts_A, quant, h)
    vmodel = velocity_model_code(s.velocity_model)
    return StepConstants(
        t_s=float(ts), step_lo=float(ts), step_hi=float(ts), rel_tol=float(s.rel_tol), split_tol=float(s.split_tol),
        split_max_width=float(s.split_max_width), velocity_model=int(vmodel), max_iter=int(s.max_iter),
        split_boxes=int(s.split_boxes),
        hypotheses=int(np.prod(s.xi_splits)) if s.xi_splits is not None else 1,
        keep_xi=bool(s.keep_xi), has_qdd_bound=s.qdd_bound is not None, axis=axis, baseline=baseline,
        diff_err=np.ascontiguousarray(diff, dtype=np.float64),
        depth=int(max(s.baselines)) if vmodel == SOUND else 1)


def for_step(c: StepConstants, s, step, spans) -> StepConstants:
    """``c`` (of settings ``s``) for one step of an uneven recording: ``step`` ``(lo, hi)`` encloses
    ``t_k - t_{k-1}`` and ``spans`` ``(J, 2)`` the baselines ``t_k - t_{k-j}`` (s, lower bounds > 0;
    :class:`verifier.clock.SampleClock`).  With ``step = (t_s, t_s)`` and ``spans`` ``j t_s`` (outward), the
    floats of ``c`` itself."""
    half_ts2_A, ts_A, quant, h, diff = _timed(s.assumptions, c.axis.shape[0], step, spans)
    axis, baseline = c.axis.copy(), c.baseline.copy()
    _fill(axis, baseline, half_ts2_A, ts_A, quant, h)
    return c._replace(step_lo=float(step[0]), step_hi=float(step[1]), axis=axis, baseline=baseline,
                      diff_err=np.ascontiguousarray(diff, dtype=np.float64))
