"""When the samples were taken: a fixed period with dropped samples, or stamps with a stated error.

The step's constants (:mod:`verifier.constants`) hold the time between samples:
the prediction's step ``t_k - t_{k-1}`` and the displacement baselines
``t_k - t_{k-j}``.  A :class:`SampleClock` encloses them for each sample of an
uneven recording (docs/soundness.md, "Time stamps"):

* ``stamp_error = 0`` (a fixed-period controller, the default): every step is
  a whole number ``m >= 1`` of periods ``t_s`` (``m = 2``: one dropped
  sample), read from the stamps to :func:`~verifier.trajfile.step_tolerance`;
  the time between two samples is ``(ticks_k - ticks_l) t_s``, rounded
  outward.  Steps of one period give the constants of a constant period
  themselves: a recording without a dropped sample is tracked bit for bit as
  before.
* ``stamp_error = delta > 0`` (jittered stamps): the true time of sample ``k``
  lies within ``delta`` of its stamp; the stamp's float is within one spacing
  of the written one, and so ``t_k - t_l`` lies in the difference of the two
  enclosures, rounded outward.  A step whose enclosure is not positive (two
  stamps closer than ``2 delta``) cannot be tracked and is refused.

Times are in s, from any common origin.
"""

from __future__ import annotations

import math

import numpy as np

from crosscert.robots.errors import TrajectoryFileError

from . import interval as I
from .constants import for_step

__all__ = ["SampleClock", "step_tolerance", "TIME_STEP_RTOL", "STAMP_ULPS", "JITTER_RTOL"]

#: Relative tolerance on the sampling step (time stamps written in decimal).
TIME_STEP_RTOL = 1e-6
#: Spacings of doubles at the time stamps' magnitude added to that tolerance:
#: an absolute (Unix epoch) stamp of 1.7e9 s is only known to 2.4e-7 s, so a
#: step between two of them is off by up to two such spacings however even
#: the clock was (two more for the period the steps are compared with).
STAMP_ULPS = 4
#: Largest relative step deviation read as imprecise stamps rather than a changed period: float32 stamps
#: near 1000 s are 6e-5 s apart (6 % of a 1 ms period); clock jitter is far smaller.
JITTER_RTOL = 0.1


def step_tolerance(t_prev: float, t: float, t_s: float) -> float:
    """Largest ``|(t - t_prev) - t_s|`` (s) a constant-period recording may show.

    ``TIME_STEP_RTOL * t_s`` for the decimal writing of the stamps, plus
    :data:`STAMP_ULPS` spacings of doubles at the stamps' magnitude (absolute
    time stamps).
    """
    return TIME_STEP_RTOL * t_s + STAMP_ULPS * math.ulp(max(abs(t_prev), abs(t)))  # numpy's spacing, no call cost


class SampleClock:
    """Enclosures of the samples' true times, built as the stamps arrive (:meth:`append`).

    Parameters
    ----------
    t_s : float
        The controller's period, s (> 0).
    stamp_error : float
        Bound on each stamp's error, s (>= 0; 0: a fixed-period controller, module docstring).
    name : str
        What messages call the recording.

    Attributes
    ----------
    even : bool
        Every step so far is one period (constant-period constants throughout).
    """

    def __init__(self, t_s: float, stamp_error: float = 0.0, *, name: str = "the recording"):
        t_s, stamp_error = float(t_s), float(stamp_error)  # t_s: the validated settings' (robots.assumptions)
        if not (np.isfinite(stamp_error) and stamp_error >= 0.0):
            raise TrajectoryFileError(f"--stamp-error must be a finite number of s >= 0, got {stamp_error!r}")
        self.t_s, self.stamp_error, self.name = t_s, stamp_error, name
        self.even = stamp_error == 0.0
        self._ticks: list[int] = []  # stamp_error = 0: periods since the first sample
        self._lo: list[float] = []  # stamp_error > 0: the true time's enclosure
        self._hi: list[float] = []
        self._stamps: list[float] = []  # as given (forget_before keeps the last)
        self._base = 0  # samples forgotten (forget_before): the lists start at this sample

    def __len__(self) -> int:
        return self._base + (len(self._ticks) if self.stamp_error == 0.0 else len(self._lo))

    def forget_before(self, k: int) -> None:
        """Drop the times of the samples before ``k`` (an online tracker reads ``depth`` samples back only)."""
        drop = min(k - self._base, len(self) - self._base - 1)
        if drop > 256:  # in chunks: one list copy per 256 samples
            for lst in (self._ticks, self._lo, self._hi, self._stamps):
                del lst[:drop]
            self._base += drop

    @classmethod
    def from_stamps(cls, t, t_s: float, stamp_error: float = 0.0, *, name: str = "the recording") -> SampleClock:
        """The clock of stamps ``t`` ``(K,)`` (s)."""
        clock = cls(t_s, stamp_error, name=name)
        for v in np.asarray(t, dtype=np.float64).ravel():
            clock.append(float(v))
        return clock

    def append(self, t: float, where: str | None = None) -> None:
        """The next sample's stamp ``t`` (s, strictly later than the last); ``where`` names its position in
        messages (``sample k`` by default)."""
        t = float(t)
        last = self._stamps[-1] if self._stamps else None
        if last is not None and not t > last:
            raise TrajectoryFileError(f"{self._at(where)}: time {t!r} does not increase (previous {last!r})")
        if self.stamp_error == 0.0:
            if last is None:
                self._ticks.append(0)
            else:
                m = self._periods(last, t, where)
                self.even &= m == 1
                self._ticks.append(self._ticks[-1] + m)
        else:
            # the stamp's float within one spacing of the written value, the true time within delta of that
            e = I.add(self.stamp_error, self.stamp_error, math.ulp(t), math.ulp(t))[1]
            lo, hi = I.sub(t, t, e, e)[0], I.add(t, t, e, e)[1]
            if self._hi and not I.sub(lo, lo, self._hi[-1], self._hi[-1])[0] > 0.0:
                raise TrajectoryFileError(
                    f"{self._at(where)}: stamps {last!r} and {t!r} s are closer than twice --stamp-error "
                    f"({self.stamp_error:.3g} s): the step between them may be zero; state a smaller stamp error if "
                    "the stamps are better than that")
            self._lo.append(lo)
            self._hi.append(hi)
        self._stamps.append(t)

    def _at(self, where: str | None) -> str:
        """Where a refused stamp is, for its message."""
        return f"{self.name}, {where or f'sample {len(self)}'}"

    def _periods(self, last: float, t: float, where: str | None) -> int:
        """The whole number of periods the step ``t - last`` is, or an error naming ``--stamp-error``."""
        step = t - last
        m = max(1, int(round(step / self.t_s)))
        off = abs(step - m * self.t_s)
        if off > step_tolerance(last, t, m * self.t_s):
            why = (f"it is {off:.3g} s off {m} period{'s' if m > 1 else ''} only (float32 stamps or clock jitter?)"
                   if off <= JITTER_RTOL * self.t_s else
                   "a fixed-period controller drops samples, it does not shift them")
            raise TrajectoryFileError(
                f"{self._at(where)}: the step {step:.9g} s is not a whole number of periods of {self.t_s:.9g} s ({why}): if the "
                "stamps jitter, state their error bound with --stamp-error (s); never resample the readings")
        return m

    def span(self, k: int, l: int) -> tuple[float, float]:
        """Enclosure of ``t_k - t_l`` (s, ``l < k``), rounded outward."""
        k, l = k - self._base, l - self._base
        if self.stamp_error == 0.0:
            return _ticks_span(float(self._ticks[k] - self._ticks[l]), self.t_s)
        with I.quiet_fp():
            lo, hi = I.sub(self._lo[k], self._hi[k], self._lo[l], self._hi[l])
        return float(lo), float(hi)

    def step_even(self, k: int, depth: int) -> bool:
        """Whether the ``depth`` steps ending at sample ``k`` (those the step reads) are one period each."""
        if self.stamp_error != 0.0:
            return False
        l = max(self._base, k - depth)
        return self._ticks[k - self._base] - self._ticks[l - self._base] == k - l

    def constants(self, c, s, k: int):
        """The step's constants for sample ``k``: ``c`` itself (those of settings ``s`` for the period
        ``t_s``) when the steps it reads are one period each, else :func:`verifier.constants.for_step`
        of this clock's enclosures."""
        if k == 0 or self.step_even(k, c.depth):  # the samples the step reads back
            return c
        step = self.span(k, k - 1)
        spans = np.array([self.span(k, k - int(j)) if int(j) <= k else step for j in s.baselines]).reshape(-1, 2)
        return _for_step_cached(c, s, step, spans)

    def times(self) -> np.ndarray:
        """Enclosures ``(K, 2)`` of the samples' times (those not forgotten), s from the first sample's
        (outward)."""
        if self.stamp_error == 0.0:
            return np.array([_ticks_span(float(t), self.t_s) for t in self._ticks]).reshape(-1, 2)
        return np.stack([np.asarray(self._lo), np.asarray(self._hi)], axis=1)

    def stamps(self) -> np.ndarray:
        """The stamps as given (those not forgotten), s."""
        return np.asarray(self._stamps, dtype=np.float64)

    def window(self, start: int, stop: int | None = None, *, reverse: bool = False) -> SampleClock:
        """The clock of samples ``start .. stop - 1`` (time-reversed with ``reverse``: the backward passes)."""
        out = SampleClock(self.t_s, self.stamp_error, name=self.name)
        if start < self._base:
            raise ValueError(f"the times before sample {self._base} were forgotten")
        start, stop = start - self._base, None if stop is None else stop - self._base
        stamps = self._stamps[start:stop]
        out._stamps = [-v for v in stamps[::-1]] if reverse else list(stamps)
        if self.stamp_error == 0.0:
            ticks = np.asarray(self._ticks[start:stop], dtype=np.int64)
            if reverse:
                ticks = ticks[-1] - ticks[::-1]
            out._ticks = [int(v) for v in ticks - ticks[0]]
            out.even = bool(np.all(np.diff(ticks) == 1))
        else:
            lo, hi = self._lo[start:stop], self._hi[start:stop]
            out.even = False
            # negation is exact: the reversed times' enclosures are those of -t, in reverse order
            out._lo, out._hi = ([-v for v in hi[::-1]], [-v for v in lo[::-1]]) if reverse else (list(lo), list(hi))
        return out


def _ticks_span(d: float, t_s: float) -> tuple[float, float]:
    """``d t_s`` rounded outward (``d`` a whole number of periods): :func:`verifier.constants.pack_constants`'
    baselines for ``d = j``."""
    with I.quiet_fp():
        lo, hi = I.mul(d, d, t_s, t_s)
    return float(lo), float(hi)


#: Constants of recent uneven steps, per ``(id(c), step, spans)``: a fixed-period clock repeats a few patterns
#: (around each dropped sample), a jittered one none (bounded either way).
_CACHE: dict = {}
_CACHE_SIZE = 512


def _for_step_cached(c, s, step, spans):
    """:func:`for_step`, remembered (:data:`_CACHE`)."""
    key = (id(c), float(step[0]), float(step[1]), spans.tobytes())
    hit = _CACHE.get(key)
    if hit is None or hit[0] is not c:  # an id reused by another configuration's constants
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.clear()
        hit = _CACHE[key] = (c, for_step(c, s, step, spans))
    return hit[1]
