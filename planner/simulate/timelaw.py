"""Time laws of a straight motion: smoothstep speed ramps, cruise through the locus, rest.

The arc length ``s(t)`` (m, or the pose unit) of a :class:`TimeLaw` is built
from segments of constant duration whose speed goes from ``v0`` to ``v1`` by a
quintic smoothstep, so the acceleration is continuous, zero at both ends and
peaks at ``RAMP_PEAK |v1 - v0| / T``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


__all__ = ["RAMP_PEAK", "ramp_length", "TimeLaw", "crossing_time_law", "bounce_time_law"]

#: Peak of the smoothstep derivative ``30 u^2 (1 - u)^2`` (at ``u = 1/2``):
#: a ramp of speed change ``dv`` over ``T`` peaks at ``|a| = RAMP_PEAK dv / T``.
RAMP_PEAK = 1.875


def ramp_length(v: float, a_peak: float) -> tuple[float, float]:
    """Duration (s) and distance (m) of a rest-to-``v`` smoothstep ramp peaking at ``a_peak``.

    ``T = 1.875 v / a_peak`` and ``D = v T / 2 = 1.875 v^2 / (2 a_peak)``.
    """
    T = RAMP_PEAK * v / a_peak
    return T, 0.5 * v * T


@dataclass(frozen=True)
class TimeLaw:
    """Piecewise arc length ``s(t)`` made of constant-speed and smoothstep-ramp segments.

    Attributes
    ----------
    segments : tuple of (t0, T, s0, v0, v1)
        Start time (s), duration (s), start arc length (m), start and end
        speeds (m/s).  Speed ramps from ``v0`` to ``v1`` as
        ``v0 + (v1 - v0) S(u)``, ``S(u) = 10u^3 - 15u^4 + 6u^5``,
        ``u = (t - t0) / T``; ``v0 == v1`` is a constant-speed segment.
    duration : float
        End time, s (the law holds the last position afterwards).
    """

    segments: tuple[tuple[float, float, float, float, float], ...]
    duration: float

    @staticmethod
    def build(s_start: float, pieces) -> "TimeLaw":
        """Chain ``pieces`` ``(T, v0, v1)`` from rest-state ``s_start`` at ``t = 0``."""
        segs = []
        t0, s0 = 0.0, float(s_start)
        for T, v0, v1 in pieces:
            if T <= 0.0:
                continue
            segs.append((t0, float(T), s0, float(v0), float(v1)))
            s0 = s0 + T * (v0 + v1) / 2.0  # both segment kinds average their end speeds
            t0 += T
        return TimeLaw(tuple(segs), t0)

    @property
    def s_start(self) -> float:
        """Arc length at ``t = 0``, m."""
        return self.segments[0][2]

    @property
    def s_end(self) -> float:
        """Arc length at the end, m."""
        t0, T, s0, v0, v1 = self.segments[-1]
        return s0 + T * (v0 + v1) / 2.0

    def evaluate(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Arc length (m), speed (m/s) and acceleration (m/s^2) at times ``t`` (s), each shape of ``t``."""
        t = np.asarray(t, dtype=float)
        starts = np.array([seg[0] for seg in self.segments])
        # Each time belongs to the last segment starting strictly before it
        # (t = 0 to the first); u is clipped so times outside [0, duration]
        # hold the end states.
        idx = np.clip(np.searchsorted(starts, t, side="left") - 1, 0, len(starts) - 1)
        seg = np.array(self.segments)[idx]
        t0, T, s0, v0, v1 = (seg[..., j] for j in range(5))
        u = np.clip((t - t0) / T, 0.0, 1.0)
        dv = v1 - v0
        step = u**3 * (10.0 + u * (-15.0 + 6.0 * u))
        dstep = 30.0 * u**2 * (1.0 - u) ** 2
        istep = u**4 * (2.5 + u * (-3.0 + u))  # integral of step over [0, u]
        s = s0 + T * (v0 * u + dv * istep)
        v = v0 + dv * step
        a = np.where((t >= 0.0) & (t <= self.duration), dv / T * dstep, 0.0)
        return s, v, a


def crossing_time_law(v_sing: float, a_peak: float, cruise: float, t_rest: float,
                      t_rest_end: float) -> TimeLaw:
    """Rest, ramp to ``v_sing``, constant speed over ``s in [-cruise, cruise]``, ramp to rest, rest.

    ``s = 0`` is the nominal crossing point.  Units: m, s, m/s, m/s^2.
    """
    T, D = ramp_length(v_sing, a_peak)
    pieces = [
        (t_rest, 0.0, 0.0),
        (T, 0.0, v_sing),
        (2.0 * cruise / v_sing, v_sing, v_sing),
        (T, v_sing, 0.0),
        (t_rest_end, 0.0, 0.0),
    ]
    return TimeLaw.build(-(cruise + D), pieces)


def bounce_time_law(v_sing: float, a_peak: float, cruise: float, t_rest: float,
                    t_rest_end: float, s_touch: float) -> TimeLaw:
    """Approach at ``v_sing`` (constant over ``2 cruise``), stop at ``s_touch``, retrace to the start.

    The motion after the touching instant mirrors the approach in time, so the
    end-effector comes back to its start, at rest.  Units: m, s.
    """
    T, D = ramp_length(v_sing, a_peak)
    tc = 2.0 * cruise / v_sing
    pieces = [
        (t_rest, 0.0, 0.0),
        (T, 0.0, v_sing),
        (tc, v_sing, v_sing),
        (T, v_sing, 0.0),
        (T, 0.0, -v_sing),
        (tc, -v_sing, -v_sing),
        (T, -v_sing, 0.0),
        (t_rest_end, 0.0, 0.0),
    ]
    return TimeLaw.build(s_touch - 2.0 * (D + cruise), pieces)
