"""The one trajectory type: a motion sampled at a fixed period, read-only.

Every sampled motion crosscert reads, plans, generates or simulates is a
:class:`Trajectory` (or a subclass that adds what its producer knows, such as
the crossing sample of a plan).  The arrays are copied once and frozen, so a
trajectory handed to the tracker cannot change under it.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from crosscert.robots.assumptions import check_bound
from crosscert.robots.errors import InputError

__all__ = ["Trajectory"]

#: Per-sample arrays, shape ``(K, n)``, besides ``q``; absent ones are None.
_SAMPLED = ("qd", "qdd", "x", "xd", "xdd")


@dataclass(frozen=True, kw_only=True, eq=False)
class Trajectory:
    """A motion sampled at ``t_k``, ``K`` samples, ``n`` joints and pose coordinates.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Sample times, s, increasing.
    q : ndarray, shape (K, n)
        Joint values, rad (encoder readings of a recording, planned joints of a plan).
    qd, qdd : ndarray, shape (K, n), or None
        Joint velocities (rad/s) and accelerations (rad/s^2) when known.
    x, xd, xdd : ndarray, shape (K, n), or None
        Pose (m), velocity (m/s) and acceleration (m/s^2) when known.
    t_s : float
        Sampling period, s (``t[1] - t[0]`` when not given).

    Raises
    ------
    InputError
        On a non-finite or badly shaped array, or a time column that does not increase.

    Notes
    -----
    Equality is identity (``eq=False``): two trajectories with equal samples are
    still two objects, and comparing arrays element-wise is the caller's choice.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray | None = None
    qdd: np.ndarray | None = None
    x: np.ndarray | None = None
    xd: np.ndarray | None = None
    xdd: np.ndarray | None = None
    t_s: float | None = None

    def __post_init__(self) -> None:
        t = _frozen("t", self.t, 1)
        q = _frozen("q", self.q, 2)
        if q.shape[0] != t.shape[0]:
            raise InputError(f"q has {q.shape[0]} samples but t has {t.shape[0]}")
        if t.shape[0] > 1 and not np.all(np.diff(t) > 0):
            raise InputError("sample times t must increase")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "q", q)
        for name in _SAMPLED:
            v = getattr(self, name)
            if v is not None:
                v = _frozen(name, v, 2)
                if v.shape != q.shape:
                    raise InputError(f"{name} has shape {v.shape}, expected {q.shape} like q")
                object.__setattr__(self, name, v)
        if self.t_s is None:
            if t.shape[0] < 2:
                raise InputError("a trajectory of one sample needs t_s")
            object.__setattr__(self, "t_s", float(t[1] - t[0]))
        else:
            object.__setattr__(self, "t_s", check_bound("t_s", self.t_s))

    @property
    def n(self) -> int:
        """Number of joints (= pose coordinates)."""
        return int(self.q.shape[1])

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def motion(self) -> Trajectory:
        """The sampled motion alone, as a plain :class:`Trajectory` (a subclass's extra fields dropped)."""
        return Trajectory(**{f.name: getattr(self, f.name) for f in fields(Trajectory)})


def _frozen(name: str, value, ndim: int) -> np.ndarray:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an array of numbers") from None
    if a.ndim != ndim:
        raise InputError(f"{name} must have {ndim} dimension(s), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name} must be finite")
    a.setflags(write=False)
    return a
