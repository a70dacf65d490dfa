"""Put an event of a continuous time law on a sample: the one sample alignment of the planner.

Plans, generated crossings, time scalings and simulations all put their
singular instant exactly on a sample time ``k t_s`` (the tracker and the
crossing criterion are read there), by delaying the law by less than one
period.  :func:`align_to_samples` is that computation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from crosscert.robots.assumptions import check_bound
from crosscert.robots import arguments as V

__all__ = ["SampleAlignment", "align_to_samples"]

#: Relative slack, in periods, when rounding a time to a sample index: an
#: instant computed on a sample up to rounding stays on that sample.
ALIGN_TOL = 1e-9


@dataclass(frozen=True)
class SampleAlignment:
    """Where a law's event lands on the sample grid ``t_k = k t_s``.

    Attributes
    ----------
    k_event : int
        Sample at the event: ``k_event * t_s == t_event + shift``.
    shift : float
        Delay of the law, s, in ``[0, t_s)``: the law's time is ``t_k - shift``.
    samples : int
        Number of samples ``K`` covering the delayed law to its end.
    """

    k_event: int
    shift: float
    samples: int


def align_to_samples(t_event: float, duration: float, t_s: float) -> SampleAlignment:
    """Delay a law of length ``duration`` (s) so its event at ``t_event`` (s) falls on a sample.

    Parameters
    ----------
    t_event : float
        Time of the event on the law's clock, s, ``0 <= t_event <= duration``.
    duration : float
        Length of the law, s.
    t_s : float
        Sampling period, s.
    """
    t_s = check_bound("t_s", t_s)
    t_event = V.number("t_event", t_event)
    duration = V.number("duration", duration)
    k = math.ceil(t_event / t_s - ALIGN_TOL)
    shift = max(0.0, k * t_s - t_event)
    samples = math.floor((duration + shift) / t_s + ALIGN_TOL) + 1
    return SampleAlignment(int(k), float(shift), int(samples))
