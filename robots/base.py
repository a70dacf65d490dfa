"""Description of a parallel robot: geometry, bounds and its loop-closure equations.

A :class:`Robot` is pure data plus the *one* symbolic definition of its
loop-closure equations ``f(x, q, xi) = 0`` (eq. (1) of the paper).  Every
derived quantity (Jacobians, determinant, numeric IK/FK) is built from that
single CasADi definition by :class:`robots.kinematics.KinematicModel`, so the
simulator, the interval tracker and the tests can never disagree on the model.

Units are SI throughout: lengths in m, angles in rad, times in s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .assumptions import Assumptions
from .errors import InputError, ModelError
from .units import PoseUnit
from .arguments import floats, vector

__all__ = ["Robot", "LoopClosure", "BenchmarkCrossing", "ReferenceMotion"]

#: Signature of a loop-closure definition: ``(x, q, xi) -> f`` on CasADi SX
#: column vectors of shapes ``(n,)``, ``(n,)``, ``(m,)``, returning ``(n,)``.
LoopClosure = Callable[..., object]


@dataclass(frozen=True, kw_only=True)
class Robot:
    """A parallel robot with ``n`` actuated joints and ``n`` pose coordinates.

    Parameters
    ----------
    name : str
        Registry key, e.g. ``"dextar"``.
    n : int
        Degrees of freedom = number of actuated joints = pose dimension.
    param_names : tuple of str, length m
        Names of the geometric parameters ``xi``, in the order ``loop_closure``
        reads them.
    xi_nominal : tuple of float, length m
        Nominal (design) values of the parameters, SI (m, rad).  A design value
        may lie slightly outside its calibrated interval (Table I of the paper
        has ``l11 = 90 mm`` against ``[89.832, 89.995] mm``); it must however lie
        within ``[xi_lo - w, xi_hi + w]``, ``w = xi_hi - xi_lo``, which catches
        unit slips.  Only the interval ``[xi_lo, xi_hi]`` is certified.
    xi_lo, xi_hi : tuple of float, length m
        Calibration interval ``[xi]`` enclosing the true parameters, SI.
    q_lo, q_hi : tuple of float, length n
        Modelled joint range, rad (m for prismatic joints).
    x_bounds : tuple (lo, hi) of tuples of float, each length n
        A box, SI, containing every pose reachable for any ``xi`` in
        ``[xi_lo, xi_hi]`` (the search domain of the interval forward
        kinematics of the first sample, and of the simulator).
    loop_closure : callable
        ``loop_closure(x, q, xi) -> casadi.SX`` with ``x`` shape ``(n,)`` (pose),
        ``q`` shape ``(n,)`` (joints, rad), ``xi`` shape ``(m,)``; returns the
        ``(n,)`` residual of eq. (1).  Only operations the interval evaluator
        supports may be used (``+ - * /``, integer powers, ``sqrt``, ``sin``,
        ``cos``).
    pose_units : tuple of PoseUnit (or ``"m"`` / ``"rad"``), length n
        Unit of each pose coordinate: ``"m"`` for a length, ``"rad"`` for an
        angle.  The one declaration of the pose's units: per-axis bounds
        (``a_max``, ``xd0``, ``tracking_a_margin``) are in these units per s or
        per s^2, and nothing combines axes of different units.
    a_max : tuple of float, length n
        The robot's physical bound on ``|x''|`` per axis, in its unit per s^2
        (m/s^2 or rad/s^2, see ``pose_units``): what the drives can produce.
    eps_q : float
        Default encoder error bound, in each joint's unit (``joint_units``):
        ``|q_meas - q_true| <= eps_q``.
    t_s : float
        Default sampling period, s.
    xd0 : tuple of float, length n
        Default bound on the initial velocity, componentwise ``|x'(0)| <= xd0``
        (the paper's ``[xd]_0``), m/s.
    xi_splits : tuple of int, length m, optional
        Recommended partition of ``[xi]`` for the tracker (``xi_splits[i]``
        equal parts along parameter ``i``; each part is tracked as its own
        geometry hypothesis).  ``None``: no partition.
    joint_offsets : tuple of (int or None), length n, optional
        ``joint_offsets[i] = j`` declares that the loop closure reads joint
        ``i`` only through ``q_i + xi_j`` (an additive encoder offset); ``None``
        where joint ``i`` has no such parameter.  The planner uses it to model
        executions that follow a Cartesian path, whose encoder readings absorb
        the unknown offset (``planner.execution``).  Checked numerically by the
        tests, not here.
    mode_sign : float, optional
        ``+1.0`` or ``-1.0``.  The assembly mode is defined as
        ``mode_sign * sign(det J_x)``, so that a robot module can align it with
        its geometric convention.
    mode_reference : callable, optional
        ``mode_reference(x, q, xi) -> int``: the assembly mode (+1/-1) of a
        regular configuration computed from the robot's geometry, without
        CasADi (e.g. a cross product).  It states the mode convention
        independently of ``mode_sign``, so that :func:`crosscert.validate` can
        check that the two agree.  ``None``: that check is not run.
    tracking_a_margin : tuple of float, length n, optional
        How far the executed end-effector acceleration may deviate from the
        planned one, per axis, in its unit per s^2: the tracking error the
        robot's controller allows, ``|x''_executed - x''_planned| <=
        tracking_a_margin``.  A planning-time certificate then bounds each
        axis by the plan's peak plus this margin (never above ``a_max``).
        Declare it only with a stated reason (a controller's specification, a
        measurement); ``None`` (default): not declared, and every axis is
        bounded by the robot's ``a_max``, the bound that holds whatever the
        controller does.
        Each entry is positive and at most ``a_max``.
    joint_units : tuple of PoseUnit (or ``"m"`` / ``"rad"``), length n, optional
        Unit of each joint coordinate: ``"rad"`` for a revolute joint, ``"m"``
        for a prismatic one (``eps_q`` and ``q_lo``/``q_hi`` are in these
        units).  ``None``: every joint is revolute.
    description : str, optional
        One-paragraph human description (source of the data, conventions).
    """

    name: str
    n: int
    param_names: tuple[str, ...]
    xi_nominal: tuple[float, ...]
    xi_lo: tuple[float, ...]
    xi_hi: tuple[float, ...]
    q_lo: tuple[float, ...]
    q_hi: tuple[float, ...]
    x_bounds: tuple[tuple[float, ...], tuple[float, ...]]
    loop_closure: LoopClosure = field(repr=False)
    pose_units: tuple[PoseUnit, ...]
    a_max: tuple[float, ...]
    eps_q: float
    t_s: float
    xd0: tuple[float, ...]
    mode_sign: float = 1.0
    xi_splits: tuple[int, ...] | None = None
    joint_offsets: tuple[int | None, ...] | None = None
    mode_reference: Callable[..., int] | None = field(default=None, repr=False, compare=False)
    tracking_a_margin: tuple[float, ...] | None = None
    joint_units: tuple[PoseUnit, ...] | None = None
    description: str = ""

    def __post_init__(self) -> None:
        """Check every field and normalise it in place (the first bad one raises ModelError, naming the robot)."""
        set_ = object.__setattr__  # frozen: normalise fields in place once
        n, m = self._check_sizes()
        self._check_calibration_box(m)
        self._check_ranges(n)
        if not callable(self.loop_closure):
            raise ModelError(f"Robot {self.name}: loop_closure must be callable")
        set_(self, "pose_units", self._checked_units(n, "pose_units", self.pose_units))
        set_(self, "joint_units", self._checked_units(n, "joint_units", self.joint_units))
        self._check_accelerations(n)
        set_(self, "xd0", floats("xd0", self.xd0, n, error=ModelError))
        self._check_parameter_layout(n, m)
        self._check_scalars()

    def _check_sizes(self) -> tuple[int, int]:
        """Check ``name``, ``n`` and ``param_names``; normalise the last two.  Returns ``(n, m)``."""
        set_ = object.__setattr__
        if not isinstance(self.name, str) or not self.name:
            raise ModelError("Robot.name must be a non-empty string")
        if isinstance(self.n, bool) or not isinstance(self.n, (int, np.integer)) or self.n < 1:
            raise ModelError(f"Robot {self.name}: n must be a positive integer, got {self.n!r}")
        n = int(self.n)
        set_(self, "n", n)
        names = tuple(self.param_names)
        if not names or not all(isinstance(s, str) and s for s in names):
            raise ModelError(f"Robot {self.name}: param_names must be non-empty strings")
        if len(set(names)) != len(names):
            raise ModelError(f"Robot {self.name}: duplicate parameter names {names}")
        m = len(names)
        set_(self, "param_names", names)
        return n, m

    def _check_calibration_box(self, m: int) -> None:
        """Check ``xi_nominal``, ``xi_lo`` and ``xi_hi`` (``m`` each, SI): non-empty intervals, each nominal
        value within one interval width of its own; store them as float tuples."""
        set_ = object.__setattr__
        nom = floats("xi_nominal", self.xi_nominal, m, error=ModelError)
        lo = floats("xi_lo", self.xi_lo, m, error=ModelError)
        hi = floats("xi_hi", self.xi_hi, m, error=ModelError)
        for i, nm in enumerate(self.param_names):
            if lo[i] > hi[i]:
                raise ModelError(f"Robot {self.name}: interval of {nm} is empty: [{lo[i]}, {hi[i]}]")
            w = hi[i] - lo[i]
            if not lo[i] - w <= nom[i] <= hi[i] + w:
                raise ModelError(
                    f"Robot {self.name}: nominal {nm} = {nom[i]} is far outside its "
                    f"interval [{lo[i]}, {hi[i]}] (wrong units?)"
                )
        set_(self, "xi_nominal", nom)
        set_(self, "xi_lo", lo)
        set_(self, "xi_hi", hi)

    def _check_ranges(self, n: int) -> None:
        """Check the joint range ``q_lo < q_hi`` and the pose box ``x_bounds`` (``n`` each, SI); store them."""
        set_ = object.__setattr__
        qlo = floats("q_lo", self.q_lo, n, error=ModelError)
        qhi = floats("q_hi", self.q_hi, n, error=ModelError)
        if any(a >= b for a, b in zip(qlo, qhi)):
            raise ModelError(f"Robot {self.name}: need q_lo < q_hi, got {qlo}, {qhi}")
        set_(self, "q_lo", qlo)
        set_(self, "q_hi", qhi)
        try:
            xb_lo, xb_hi = self.x_bounds
        except (TypeError, ValueError) as exc:
            raise ModelError(f"Robot {self.name}: x_bounds must be a pair (lo, hi)") from exc
        xb_lo = floats("x_bounds[0]", xb_lo, n, error=ModelError)
        xb_hi = floats("x_bounds[1]", xb_hi, n, error=ModelError)
        if any(a >= b for a, b in zip(xb_lo, xb_hi)):
            raise ModelError(f"Robot {self.name}: x_bounds lo must be < hi, got {xb_lo}, {xb_hi}")
        set_(self, "x_bounds", (xb_lo, xb_hi))

    def _check_accelerations(self, n: int) -> None:
        """Check ``a_max`` and ``tracking_a_margin`` (``n`` each, per pose axis, m/s^2 or rad/s^2): the margin
        positive and at most ``a_max``; store them."""
        set_ = object.__setattr__
        amax = floats("a_max", self.a_max, n, error=ModelError)
        set_(self, "a_max", amax)
        if self.tracking_a_margin is not None:
            margin = floats("tracking_a_margin", self.tracking_a_margin, n, error=ModelError)
            bad = [i for i in range(n) if not 0 < margin[i] <= amax[i]]
            if bad:
                i = bad[0]
                raise ModelError(
                    f"Robot {self.name}: tracking_a_margin[{i}] = {margin[i]:g} {self.pose_units[i].acceleration} "
                    f"must be positive and at most a_max[{i}] = {amax[i]:g} {self.pose_units[i].acceleration} "
                    "(or declare no margin: tracking_a_margin=None)"
                )
            set_(self, "tracking_a_margin", margin)

    def _check_parameter_layout(self, n: int, m: int) -> None:
        """Check ``xi_splits`` (a positive count per parameter) and ``joint_offsets`` (per joint, a distinct
        parameter index in ``[0, m)`` or None); store them as int tuples."""
        set_ = object.__setattr__
        if self.xi_splits is not None:
            splits = tuple(int(v) for v in self.xi_splits)
            if len(splits) != len(self.xi_nominal) or any(v < 1 for v in splits):
                raise ModelError(f"Robot {self.name}: xi_splits needs one positive count per parameter, got {self.xi_splits}")
            set_(self, "xi_splits", splits)
        if self.joint_offsets is not None:
            offs = tuple(None if j is None else int(j) for j in self.joint_offsets)
            used = [j for j in offs if j is not None]
            if len(offs) != n or any(not 0 <= j < m for j in used) or len(set(used)) != len(used):
                raise ModelError(
                    f"Robot {self.name}: joint_offsets needs, per joint, a distinct parameter index in "
                    f"[0, {m}) or None, got {self.joint_offsets}"
                )
            set_(self, "joint_offsets", offs)

    def _check_scalars(self) -> None:
        """Check ``eps_q``, ``t_s``, the default bounds (:class:`~robots.assumptions.Assumptions`),
        ``mode_sign``, ``mode_reference`` and ``description``; normalise the numbers."""
        set_ = object.__setattr__
        for attr in ("eps_q", "t_s"):
            try:
                set_(self, attr, float(getattr(self, attr)))
            except (TypeError, ValueError) as exc:
                raise ModelError(f"Robot {self.name}: {attr} must be a number") from exc
        try:  # the default bounds obey the one rule of each (robots.assumptions), not a copy of it
            Assumptions.for_robot(self)
        except InputError as exc:
            raise ModelError(f"Robot {self.name}: {exc}") from None
        if self.mode_sign not in (1, -1):
            raise ModelError(f"Robot {self.name}: mode_sign must be +1 or -1, got {self.mode_sign!r}")
        set_(self, "mode_sign", float(self.mode_sign))
        if self.mode_reference is not None and not callable(self.mode_reference):
            raise ModelError(f"Robot {self.name}: mode_reference must be callable or None")
        if not isinstance(self.description, str):
            raise ModelError(f"Robot {self.name}: description must be a string")

    def _checked_units(self, n: int, name: str, value) -> tuple[PoseUnit, ...]:
        """``value`` (field ``name``) as ``n`` :class:`PoseUnit` values, or ModelError naming the allowed ones."""
        if value is None:
            value = (PoseUnit.RADIAN,) * n
        try:
            if isinstance(value, str):
                raise TypeError
            units = tuple(value)
        except TypeError:
            raise ModelError(f"Robot {self.name}: {name} must be a tuple of units, one per coordinate") from None
        what = "pose axis" if name == "pose_units" else "joint"
        if len(units) != n:
            raise ModelError(f"Robot {self.name}: {name} needs one unit per {what} ({n}), got {len(units)}")
        out = []
        for i, u in enumerate(units):
            try:
                out.append(PoseUnit(u))
            except ValueError:
                raise ModelError(f"Robot {self.name}: {name}[{i}] = {u!r} is not a {what.split()[0]} unit; use one of "
                                 f"{', '.join(repr(p.value) for p in PoseUnit)}") from None
        return tuple(out)

    # ----------------------------------------------------------------- units
    @property
    def assumptions(self) -> Assumptions:
        """The robot's default bounds and calibration box as one :class:`~robots.assumptions.Assumptions`."""
        return Assumptions.for_robot(self)

    @property
    def acceleration_units(self) -> tuple[str, ...]:
        """Unit of each axis' acceleration (``"m/s^2"`` or ``"rad/s^2"``), from ``pose_units``."""
        return tuple(u.acceleration for u in self.pose_units)

    @property
    def velocity_units(self) -> tuple[str, ...]:
        """Unit of each axis' velocity (``"m/s"`` or ``"rad/s"``), from ``pose_units``."""
        return tuple(u.velocity for u in self.pose_units)

    @property
    def mixed_units(self) -> bool:
        """Whether the pose mixes lengths and angles (then no one number can stand for every axis)."""
        return len(set(self.pose_units)) > 1

    # ----------------------------------------------------------------- arrays
    @property
    def m(self) -> int:
        """Number of geometric parameters ``len(xi)``."""
        return len(self.param_names)

    @property
    def xi_nominal_array(self) -> np.ndarray:
        """Nominal parameters, shape ``(m,)``, SI."""
        return np.array(self.xi_nominal, dtype=float)

    @property
    def xi_lo_array(self) -> np.ndarray:
        """Lower ends of the calibration intervals, shape ``(m,)``, SI."""
        return np.array(self.xi_lo, dtype=float)

    @property
    def xi_hi_array(self) -> np.ndarray:
        """Upper ends of the calibration intervals, shape ``(m,)``, SI."""
        return np.array(self.xi_hi, dtype=float)

    @property
    def xi_center(self) -> np.ndarray:
        """Midpoint of the calibration box, shape ``(m,)``, SI (always inside it)."""
        return 0.5 * (self.xi_lo_array + self.xi_hi_array)

    @property
    def q_lo_array(self) -> np.ndarray:
        """Lower joint limits, shape ``(n,)``, rad."""
        return np.array(self.q_lo, dtype=float)

    @property
    def q_hi_array(self) -> np.ndarray:
        """Upper joint limits, shape ``(n,)``, rad."""
        return np.array(self.q_hi, dtype=float)

    @property
    def x_lo_array(self) -> np.ndarray:
        """Lower corner of the workspace box ``x_bounds``, shape ``(n,)``, SI."""
        return np.array(self.x_bounds[0], dtype=float)

    @property
    def x_hi_array(self) -> np.ndarray:
        """Upper corner of the workspace box ``x_bounds``, shape ``(n,)``, SI."""
        return np.array(self.x_bounds[1], dtype=float)

    @property
    def a_max_array(self) -> np.ndarray:
        """The robot's physical acceleration bound, shape ``(n,)``, per axis in ``acceleration_units``."""
        return np.array(self.a_max, dtype=float)

    def xi_in_box(self, xi, *, tol: float = 0.0) -> bool:
        """Whether ``xi`` (shape ``(m,)``) lies in ``[xi_lo - tol, xi_hi + tol]``."""
        xi = np.asarray(xi, dtype=float)
        return bool(
            xi.shape == (self.m,)
            and np.all(xi >= self.xi_lo_array - tol)
            and np.all(xi <= self.xi_hi_array + tol)
        )


@dataclass(frozen=True, eq=False)
class BenchmarkCrossing:
    """A robot's reference crossing of its Type 2 locus, for one geometry.

    Attributes
    ----------
    point : ndarray, shape (n,)
        A point of the Type 2 locus, m (SI pose units).
    direction : ndarray, shape (n,)
        Unit direction of motion through it.
    q_point : ndarray, shape (n,)
        Joints at ``point`` on the working branch, rad (a valid ``working_guess``).
    xi : ndarray, shape (m,)
        Geometry ``point`` was computed for.
    """

    point: np.ndarray
    direction: np.ndarray
    q_point: np.ndarray
    xi: np.ndarray

    def __post_init__(self) -> None:
        for name in ("point", "direction", "q_point", "xi"):
            object.__setattr__(self, name, vector(name, getattr(self, name), error=ModelError))


@dataclass(frozen=True, eq=False)
class ReferenceMotion:
    """A robot's reference motion for ``simulate`` when it ships no crossing: a straight segment at rest ends.

    Attributes
    ----------
    start, goal : ndarray, shape (n,)
        End poses, SI (m, rad); the segment between them is regular.
    q_start : ndarray, shape (n,)
        Joints at ``start`` (a working-branch guess), rad or m.
    xi : ndarray, shape (m,)
        Geometry the joints were computed for.
    """

    start: np.ndarray
    goal: np.ndarray
    q_start: np.ndarray
    xi: np.ndarray

    def __post_init__(self) -> None:
        for name in ("start", "goal", "q_start", "xi"):
            object.__setattr__(self, name, vector(name, getattr(self, name), error=ModelError))
