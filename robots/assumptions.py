"""What a certificate assumes about the robot and its readings: one value, checked once.

:class:`Assumptions` is the one owner of the bounds a tracker run rests on —
sampling period, reading error, acceleration bound, initial speed bound,
speed bound, calibration box and the drift model of the reading error.  Each
field has one rule (:data:`RULES`), applied once when the value is built;
the arrays are read-only, so a holder (``TrackerSettings``,
``RecordingBounds``, a robot's defaults) can share one without copying or
checking it again.

Units are SI and per coordinate: the reading error of joint ``i`` is in that
joint's unit (rad for a revolute joint, m for a prismatic one,
``Robot.joint_units``); the acceleration and speed bounds of pose axis ``i``
are in its unit per s^2 and per s (``Robot.pose_units``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Callable

import numpy as np

from .errors import InputError
from .units import PoseUnit

__all__ = ["Assumptions", "RULES", "check_bound"]


@dataclass(frozen=True)
class _Context:
    """What a rule needs besides the value: the dimension and the units, for shapes and messages."""

    n: int
    joint_units: tuple[PoseUnit, ...] | None
    pose_units: tuple[PoseUnit, ...] | None

    def per_joint(self) -> str:
        return _unit_text(self.joint_units, "", "each joint's unit (rad or m)")

    def per_axis(self, rate: str) -> str:
        return _unit_text(self.pose_units, rate, f"each axis' unit{rate} (m{rate} or rad{rate})")


def _unit_text(units, rate: str, unknown: str) -> str:
    if units is None:
        return unknown
    names = [f"{u.value}{rate}" for u in units]
    return names[0] if len(set(names)) == 1 else "(" + ", ".join(names) + ")"


def _array(name: str, value, ctx: _Context, *, unit: str, inf: bool = False, zero: bool = False) -> np.ndarray:
    """``value`` as a read-only ``(n,)`` float array (one number stands for ``n``); every entry > 0 (>= 0 with
    ``zero``), finite unless ``inf``."""
    try:
        a = np.array(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number or one number per coordinate, in {unit}; got {value!r}") from None
    if a.size == 1:
        a = np.full(ctx.n, a[0])
    if a.shape != (ctx.n,):
        raise InputError(f"{name} needs 1 or {ctx.n} entries, in {unit}; got {a.size}")
    ok = (a >= 0) if zero else (a > 0)
    if not inf:
        ok &= np.isfinite(a)
    if np.any(np.isnan(a)) or not np.all(ok):
        what = "non-negative" if zero else "positive"
        raise InputError(f"{name} must be {what}{'' if inf else ' and finite'}, in {unit}; got {a.tolist()}")
    a.setflags(write=False)
    return a


# ------------------------------------------------------------------ the rules, one per field
def _t_s(v, ctx):
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"sampling period t_s must be a number of seconds, got {v!r}") from None
    if isinstance(v, (bool, np.bool_)) or not (math.isfinite(f) and f > 0):
        raise InputError(f"sampling period t_s must be positive and finite, in s; got {v!r}")
    return f


def _eps_q(v, ctx):
    return _array("reading error eps_q", v, ctx, unit=ctx.per_joint())


def _a_max(v, ctx):
    return _array("acceleration bound a_max", v, ctx, unit=ctx.per_axis("/s^2"))


def _xd0(v, ctx):
    # 0 is a state, not a degenerate bound: a run known to start at rest
    return _array("initial speed bound xd0", np.inf if v is None else v, ctx, unit=ctx.per_axis("/s"), inf=True,
                  zero=True)


def _v_max(v, ctx):
    return _array("speed bound v_max", np.inf if v is None else v, ctx, unit=ctx.per_axis("/s"), inf=True)


def _xi_box(v, ctx):
    if v is None:
        return None
    try:
        lo, hi = (np.array(b, dtype=np.float64).reshape(-1) for b in v)
    except (TypeError, ValueError):
        raise InputError(f"calibration box xi_box must be a pair (xi_lo, xi_hi) of vectors, SI; got {v!r}") from None
    if lo.shape != hi.shape or lo.size == 0 or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise InputError("calibration box xi_box: xi_lo and xi_hi must be finite vectors of one length, SI")
    if np.any(lo > hi):
        raise InputError(f"calibration box is empty: xi_lo = {lo.tolist()}, xi_hi = {hi.tolist()}")
    lo.setflags(write=False)
    hi.setflags(write=False)
    return lo, hi


def _drift(v, ctx):
    if v is None:
        return None
    try:
        fast, rate = v
    except (TypeError, ValueError):
        raise InputError(f"drift must be a pair (eps_q_fast, drift_rate) or None, got {v!r}") from None
    if fast is None or rate is None:
        raise InputError("eps_q_fast and drift_rate go together: give both or neither")
    unit = ctx.per_joint()
    return (_array("eps_q_fast", fast, ctx, unit=unit, zero=True),
            _array("drift_rate", rate, ctx, unit=f"{unit}/s" if "(" not in unit else unit + " per s", zero=True))


#: The one rule of each field: ``rule(value, context) -> normalised value``, InputError if it is not admissible.
RULES: dict[str, Callable] = {
    "t_s": _t_s,
    "eps_q": _eps_q,
    "a_max": _a_max,
    "xd0": _xd0,
    "v_max": _v_max,
    "xi_box": _xi_box,
    "drift": _drift,
}


def _units(value, n: int, name: str) -> tuple[PoseUnit, ...] | None:
    if value is None:
        return None
    units = tuple(PoseUnit(u) for u in value)
    if len(units) != n:
        raise InputError(f"{name} needs one unit per coordinate ({n}), got {len(units)}")
    return units


def check_bound(name: str, value, n: int | None = None, *, joint_units=None, pose_units=None):
    """One field checked by its rule, outside an :class:`Assumptions` (a value given before the robot is
    known, or a function's own argument); returns the normalised value.

    Without ``n`` a single number is checked as such and returned as a float.
    """
    scalar = n is None and np.ndim(value) == 0
    if n is None:
        n = max(int(np.size(value)), 1)
    ctx = _Context(n, _units(joint_units, n, "joint_units"), _units(pose_units, n, "pose_units"))
    out = RULES[name](value, ctx)
    return float(out[0]) if scalar and isinstance(out, np.ndarray) else out


@dataclass(frozen=True, eq=False, kw_only=True)
class Assumptions:
    """The bounds a certificate assumes, SI, per coordinate, checked once at construction.

    Parameters
    ----------
    t_s : float
        Sampling period, s (> 0).
    eps_q : float or array (n,)
        Reading error of each joint, in its unit (``joint_units``: rad or m):
        ``|q_meas - q_true| <= eps_q`` (> 0).
    a_max : float or array (n,)
        Acceleration bound of each pose axis, in its unit per s^2
        (``pose_units``): ``|x''_i| <= a_max_i`` (> 0).
    xd0 : float or array (n,), optional
        Initial speed bound per pose axis, its unit per s: ``|x'(0)| <= xd0``
        (>= 0; ``None`` or ``inf``: none).
    v_max : float or array (n,), optional
        Speed bound per pose axis, its unit per s (> 0; ``None``: none).
    xi_box : pair of arrays (m,), optional
        Calibration box ``(xi_lo, xi_hi)`` enclosing the true geometry, SI
        (``None``: the model's own box).
    drift : pair (eps_q_fast, drift_rate), optional
        A reading error that drifts slowly: besides ``|e_k| <= eps_q`` the
        error is a part bounded by ``eps_q_fast`` (joint units, >= 0) plus a
        part changing by at most ``drift_rate`` per s (>= 0), so a difference
        over ``j`` samples errs by at most ``min(2 eps_q, 2 eps_q_fast +
        drift_rate j t_s)``.  ``None``: readings err independently.
    joint_units, pose_units : tuple of PoseUnit, optional
        Units of the joints and pose axes, for messages (``None``: not known).
    n : int, optional
        Number of joints = pose axes; inferred from the longest vector given.

    Attributes
    ----------
    Every parameter, normalised: arrays of shape ``(n,)`` (read-only), ``xd0``
    and ``v_max`` with ``inf`` for "none", ``n`` an int.  ``eps_q_fast``,
    ``drift_rate``, ``xi_lo``, ``xi_hi`` read the pairs.

    Raises
    ------
    InputError
        On the first field its rule (:data:`RULES`) refuses, naming the field, its unit and the value.
    """

    t_s: float
    eps_q: np.ndarray
    a_max: np.ndarray
    xd0: np.ndarray | None = None
    v_max: np.ndarray | None = None
    xi_box: tuple[np.ndarray, np.ndarray] | None = None
    drift: tuple[np.ndarray, np.ndarray] | None = None
    joint_units: tuple[PoseUnit, ...] | None = None
    pose_units: tuple[PoseUnit, ...] | None = None
    n: int | None = None

    def __post_init__(self) -> None:
        n = self.n
        if n is None:
            sizes = [np.size(getattr(self, k)) for k in ("eps_q", "a_max", "xd0", "v_max")
                     if getattr(self, k) is not None]
            sizes += [len(u) for u in (self.joint_units, self.pose_units) if u is not None]
            n = max(sizes)
        if isinstance(n, bool) or int(n) != n or n < 1:
            raise InputError(f"n must be a positive integer, got {n!r}")
        n = int(n)
        ctx = _Context(n, _units(self.joint_units, n, "joint_units"), _units(self.pose_units, n, "pose_units"))
        set_ = object.__setattr__  # frozen: normalise each field once, by its rule
        set_(self, "n", n)
        set_(self, "joint_units", ctx.joint_units)
        set_(self, "pose_units", ctx.pose_units)
        for name, rule in RULES.items():
            set_(self, name, rule(getattr(self, name), ctx))

    @classmethod
    def for_robot(cls, robot, **overrides) -> Assumptions:
        """The robot's declared bounds (``t_s``, ``eps_q``, ``a_max``, ``xd0``, calibration box) and units, with
        keyword overrides of any field (``None`` values are ignored)."""
        args = dict(t_s=robot.t_s, eps_q=robot.eps_q, a_max=robot.a_max, xd0=robot.xd0,
                    xi_box=(robot.xi_lo, robot.xi_hi), joint_units=robot.joint_units, pose_units=robot.pose_units,
                    n=robot.n)
        args.update({k: v for k, v in overrides.items() if v is not None})
        return cls(**args)

    def with_(self, **changes) -> Assumptions:
        """A new value with some fields changed (checked like any other)."""
        return replace(self, **changes)

    # the pairs, by name
    @property
    def eps_q_fast(self) -> np.ndarray | None:
        """Drift model: the part of the reading error not bound to drift, joint units (``None``: no drift model)."""
        return None if self.drift is None else self.drift[0]

    @property
    def drift_rate(self) -> np.ndarray | None:
        """Drift model: how fast the rest of the reading error may change, joint units per s."""
        return None if self.drift is None else self.drift[1]

    @property
    def xi_lo(self) -> np.ndarray | None:
        """Lower corner of the calibration box, SI (``None``: not given)."""
        return None if self.xi_box is None else self.xi_box[0]

    @property
    def xi_hi(self) -> np.ndarray | None:
        """Upper corner of the calibration box, SI (``None``: not given)."""
        return None if self.xi_box is None else self.xi_box[1]

    def unit(self, name: str) -> str:
        """The unit of field ``name`` as text (one unit, or one per coordinate in parentheses), for messages
        and help."""
        ctx = _Context(self.n, self.joint_units, self.pose_units)
        units = {"t_s": "s", "eps_q": ctx.per_joint(), "a_max": ctx.per_axis("/s^2"), "xd0": ctx.per_axis("/s"),
                 "v_max": ctx.per_axis("/s"), "xi_box": "SI", "drift": ctx.per_joint()}
        return units[name]

    def summary(self) -> dict:
        """The fields as plain numbers and lists (for a certificate's JSON)."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, np.ndarray):
                v = v.tolist()
            elif isinstance(v, tuple):
                v = [x.tolist() if isinstance(x, np.ndarray) else str(x) for x in v]
            out[f.name] = v
        return out


# ------------------------------------------------------------------ holders
#: An InitVar of a holder that was not given (``None`` is a value there: "no bound").
UNSET = object()


def held(current: Assumptions | None, given: dict, **fixed) -> Assumptions:
    """The assumptions a holder keeps: ``current`` with the fields ``given`` by keyword changed.

    For the ``__post_init__`` of a dataclass that holds one :class:`Assumptions`
    and takes its fields as InitVars (``TrackerSettings``, ``RecordingBounds``):
    values equal to :data:`UNSET` were not given; values that *are* the held
    ones (what :func:`dataclasses.replace` hands back) change nothing, so a
    copy with other options changed keeps the held value unchecked.
    ``eps_q_fast``/``drift_rate`` become the ``drift`` pair, ``xi_lo``/``xi_hi``
    the ``xi_box`` pair.  ``fixed`` (e.g. ``n``) applies when a new value is built.
    """
    given = {k: v for k, v in given.items() if v is not UNSET}
    if current is not None:
        given = {k: v for k, v in given.items() if v is not getattr(current, k)}
        if not given:
            return current
    for pair, (a, b) in (("drift", ("eps_q_fast", "drift_rate")), ("xi_box", ("xi_lo", "xi_hi"))):
        if a in given or b in given:
            va = given.pop(a, None if current is None else getattr(current, a))
            vb = given.pop(b, None if current is None else getattr(current, b))
            given[pair] = None if va is None and vb is None else (va, vb)
    if current is not None:
        return current.with_(**given)
    missing = [k for k in ("t_s", "eps_q", "a_max") if k not in given]
    if missing:
        raise InputError(f"the assumptions need {', '.join(missing)} (or assumptions=Assumptions(...))")
    return Assumptions(**given, **fixed)


def reader(field: str, *, none_if_inf: bool = False) -> property:
    """A property reading ``field`` of the holder's ``assumptions`` (``None`` for an all-``inf`` bound with
    ``none_if_inf``)."""
    def get(self):
        v = getattr(self.assumptions, field)
        return None if none_if_inf and v is not None and np.all(np.isinf(v)) else v

    return property(get, doc=f"``{field}`` of the held :class:`~robots.assumptions.Assumptions`.")
