"""The online window: :class:`FixedLagWindow`, the mode of each sample certified with a fixed lag."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from crosscert.robots.errors import InputError

from ..settings import TrackerSettings
from ..step import Backend, configure, partition_xi
from ..tracker import Tracker
from .passes import hull_of_mode, reading_solutions, run_pass

__all__ = ["FixedLagWindow", "LagResult"]

#: Resolution (m) of the forward-kinematics enumeration of :class:`FixedLagWindow` (once per sample
#: and hypothesis: coarser than the whole-recording passes' 1e-5 m, which splits the locus finely).
_LAG_FK_TOL = 1e-4
#: Rows (hypothesis, geometry sub-box) per kernel call of :class:`FixedLagWindow`: small, so that the
#: rows left once the answer is settled are not run (the first call holds one row of each hypothesis).
_LAG_BATCH = 2


@dataclass(frozen=True)
class LagResult:
    """What a :class:`FixedLagWindow` knows after reading sample ``k``.

    Attributes
    ----------
    k : int
        Index of the reading just fed.
    mode_now : int
        Mode certified at sample ``k`` (+1 / -1, 0 not certified): the
        tracker's, or the one left when the other final-mode hypothesis over
        the last ``lag + 1`` samples is refuted.
    lagged : int
        Index ``k - lag`` of the sample whose mode ``lagged_mode`` is (-1
        before ``lag`` samples were read).
    lagged_mode : int
        Mode certified at sample ``k - lag`` from the readings up to ``k``.
    consistent : bool
        False once every geometry hypothesis of the tracker became empty.
    """

    k: int
    mode_now: int
    lagged: int
    lagged_mode: int
    consistent: bool


class FixedLagWindow:
    """Window reasoning online, with a fixed lag: the mode of sample ``k`` certified from the readings up to ``k + lag``.

    After each reading the forward tracker advances; when its mode at the
    newest sample ``k`` or at ``k - lag`` is not certified, one backward pass
    per final-mode hypothesis ("the pose at ``k`` is in mode ``m``") runs over
    the last ``lag + 1`` samples, from the hull of that mode's
    forward-kinematics solutions intersected with the tracker's box at ``k``
    and inside the tracker's boxes (:func:`track_window`'s backward pass on a
    window ending at ``k``).  A hypothesis whose geometry sub-boxes all die is
    refuted: the mode at ``k`` is the other one.  The mode at ``k - lag`` is
    the one every surviving sub-box of every surviving hypothesis certifies.
    Rows (hypothesis, sub-box) run a pair at a time, and those that can no
    longer change either answer are skipped (:meth:`_window`); the forward
    kinematics of the newest reading is enumerated once per sub-box.

    Parameters
    ----------
    model : verifier.model.IntervalModel
    settings : TrackerSettings
    x0 : (lo, hi)
        Initial pose box ``(n,)``, m.
    lag : int
        Samples of look-ahead (>= 1).
    xi_box : (lo, hi), optional
    backend : {"compiled", "numpy"}
    parallel : bool
        Compiled backend: the rows of a window call over the thread slots (the
        pair of each call, one per hypothesis, runs on two cores; the same
        answers).
    """

    def __init__(self, model, settings: TrackerSettings, x0, *, lag: int, xi_box=None,
                 backend: str | Backend = Backend.COMPILED, parallel: bool = True):
        if isinstance(lag, bool) or int(lag) != lag or lag < 1:
            raise InputError(f"lag must be a positive number of samples, got {lag!r}")
        self.model, self.lag, self.backend = model, int(lag), str(Backend(backend))
        s = settings.validated(model.n)
        self.settings = s
        self.tracker = Tracker(model, settings, x0, xi_box=xi_box, backend=backend)
        XI = model.xi_box() if xi_box is None else tuple(np.asarray(v, dtype=np.float64) for v in xi_box)
        lo, hi = partition_xi((XI[0][None, :], XI[1][None, :]), s.xi_splits)
        self.xi_rows = (np.ascontiguousarray(lo[0]), np.ascontiguousarray(hi[0]))
        # keep_xi: within a window the sub-box is contracted by each sample's loop closure in turn
        self.cfg_b = configure(model, replace(s, xi_splits=None, xd0=None, keep_xi=True), backend,
                               parallel=parallel)
        L, n = self.lag + 1, model.n
        # the last L samples newest first, the order of the backward pass: readings (rad), the tracker's
        # pose boxes (m) and its velocity boxes of the reversed motion ([-hi, -lo], m/s), its modes
        self._q = np.zeros((L, n))
        self._x = np.zeros((L, 2, n))
        self._xd_rev = np.zeros((L, 2, n))
        self._mode = np.zeros(L, np.int64)

    def update(self, q) -> LagResult:
        """Feed the reading ``q`` ``(n,)``, rad."""
        r = self.tracker.update(q)
        k = r.k
        for buf in (self._q, self._x, self._xd_rev, self._mode):
            buf[1:] = buf[:-1]  # one slot older (numpy copies overlapping ranges correctly)
        self._q[0] = np.asarray(q, dtype=np.float64)
        self._x[0] = r.x
        self._xd_rev[0, 0], self._xd_rev[0, 1] = -r.xd[1], -r.xd[0]  # negation is exact
        self._mode[0] = r.mode
        j = k - self.lag
        if not r.consistent:
            return LagResult(k, 0, j if j >= 0 else -1, 0, False)
        if j < 0:
            return LagResult(k, r.mode, -1, 0, True)
        lagged_fwd = int(self._mode[-1])
        if r.mode != 0 and lagged_fwd != 0:
            return LagResult(k, r.mode, j, lagged_fwd, True)
        alive_modes, lagged_modes = self._window(need_now=r.mode == 0, need_lagged=lagged_fwd == 0)
        mode_now = r.mode if r.mode != 0 or len(alive_modes) != 1 else alive_modes[0]
        lagged = lagged_fwd
        if lagged == 0 and lagged_modes and all(v == lagged_modes[0] for v in lagged_modes):
            lagged = int(lagged_modes[0])
        return LagResult(k, int(mode_now), j, int(lagged), True)

    def _window(self, need_now: bool, need_lagged: bool):
        """Backward passes over the window, a few (hypothesis, geometry sub-box) rows per ``advance`` call,
        only while a row can still change the answer: the final modes not refuted (``need_now``: the
        tracker's mode at ``k`` is open) and the modes the surviving rows certify at ``k - lag``
        (``need_lagged``).

        A hypothesis is alive once one of its rows survives, and the lagged mode stays open once a surviving
        row certifies none or two disagree; rows that cannot change either are never run.  The answer is
        therefore the one all the rows give.  Returns the alive modes and the surviving rows' lagged modes.
        """
        search = (self._x[0, 0], self._x[0, 1])
        P = self.xi_rows[0].shape[0]
        sols = {}
        alive, lagged_modes = [], []

        def useful(m):
            open_lag = need_lagged and not (0 in lagged_modes or len(set(lagged_modes)) > 1)
            return (need_now and m not in alive) or open_lag

        # rows interleaved by hypothesis, so that the first call can show both alive
        todo = [(m, p) for p in range(P) for m in (1, -1)]
        while todo:
            batch, rest = [], []
            for m, p in todo:
                if not useful(m):
                    continue
                if len(batch) == _LAG_BATCH:
                    rest.append((m, p))
                    continue
                if p not in sols:  # one enumeration of the newest reading's poses serves both hypotheses
                    sols[p] = reading_solutions(self.model, self._q[0], self.settings,
                                         (self.xi_rows[0][p], self.xi_rows[1][p]), self.backend, search, _LAG_FK_TOL)
                box = hull_of_mode(sols[p], m, search)
                if box is not None:
                    batch.append((m, p, np.maximum(box[0], search[0]), np.minimum(box[1], search[1])))
            todo = rest
            if not batch:
                continue
            hyp = np.array([b[0] for b in batch])
            rows = np.array([b[1] for b in batch])
            shape = (len(batch),) + self._x.shape
            prior = (np.broadcast_to(self._x, shape), np.broadcast_to(self._xd_rev, shape))
            _, _, md, bad, _ = run_pass(self.cfg_b, self._q, (np.stack([b[2] for b in batch]), np.stack([b[3] for b in batch])),
                                 (self.xi_rows[0][rows], self.xi_rows[1][rows]), prior)
            live = (bad < 0) & ~((md[:, 0] != 0) & (md[:, 0] != hyp))
            for m in (1, -1):
                if m not in alive and np.any(live & (hyp == m)):
                    alive.append(m)
            lagged_modes.extend(md[live, -1].tolist())
        return alive, lagged_modes
