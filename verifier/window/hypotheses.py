"""The hypothesis engine: the rows under one final mode, their rounds of passes, halving and one-motion step.

:class:`Hypothesis` holds the rows of "the last pose is in mode ``m``" and
drops those a pass refutes; :func:`decide` runs the rounds of the
hypotheses (:func:`_round`), halving surviving geometry sub-boxes along the
parameter that spreads the pose most (:func:`_pose_spread`, :func:`_bisect`),
asking the explainer and running the one-motion step once the budget of
sub-boxes is spent.
"""

from __future__ import annotations

import numpy as np

from .. import interval as I
from ..linalg import point_inverse
from ..motion_model import contract_tubes
from ..one_motion import evaluate_tape, one_motion_rows
from ..step import Backend
from .explain import Explanation
from .passes import tube_hull
from .results import HypothesisResult, HypothesisStatus, Refutation

__all__ = ["ONE_MOTION_SHRINK", "ONE_MOTION_ROUNDS", "Hypothesis", "decide"]

#: A one-motion step that narrows some sub-box by this fraction of a parameter's width (or drops a row) earns
#: the hypothesis another round of passes without halving, up to :data:`ONE_MOTION_ROUNDS` times.
ONE_MOTION_SHRINK = 0.1
#: Rounds of passes a hypothesis may run after one-motion steps when its budget of sub-boxes is spent.
ONE_MOTION_ROUNDS = 6
#: Velocity widths above this (m/s) count as this much when measuring progress (unbounded tubes).
_WIDTH_CAP = 1e3


def _width(x, xd):
    w = np.minimum(x[..., 1, :] - x[..., 0, :], _WIDTH_CAP).sum() + np.minimum(xd[..., 1, :] - xd[..., 0, :],
                                                                                 _WIDTH_CAP).sum()
    return float(w)


def _pose_spread(model, x, q, xi_lo, xi_hi, compiled: bool = False):
    """How wide each parameter's width alone makes the pose, per geometry sub-box: ``(R, m)``, m.

    For row ``r`` and parameter ``i``: ``|C| w(f(x_r, q_r, xi_i))`` summed over the pose coordinates, ``f``
    the loop closure evaluated at the midpoint of the pose box ``x`` ``(R, 2, n)`` and of the sub-box except
    parameter ``i``, which keeps its width, with the reading ``q`` (``(n,)``, or ``(R, n)``: one per row), and
    ``C`` the inverse of ``J_x`` there (the first-order pose error of that parameter's uncertainty).  A
    heuristic for where to split: it decides no box.  Every operation is elementwise over the rows, so a
    row's result does not depend on the rows evaluated with it.  ``compiled``: the tapes by
    :func:`verifier.one_motion.evaluate_tape`'s compiled kernel (the same floats).
    """
    R, m = xi_lo.shape
    n = model.n
    xm = np.repeat(I.midpoint(x[:, 0], x[:, 1]), m, axis=0)
    qm = np.repeat(np.broadcast_to(np.asarray(q, dtype=np.float64), (R, n)), m, axis=0)
    mid = I.midpoint(xi_lo, xi_hi)
    lo, hi = np.repeat(mid, m, axis=0), np.repeat(mid, m, axis=0)
    one = np.tile(np.eye(m, dtype=bool), (R, 1))
    lo[one], hi[one] = xi_lo.reshape(-1), xi_hi.reshape(-1)
    F = evaluate_tape(model.tape_f, [(xm, xm), (qm, qm), (lo, hi)], compiled)[0]
    J = evaluate_tape(model.tape_jx, [(xm, xm), (qm, qm), (np.repeat(mid, m, axis=0),) * 2], compiled)[0]
    C = point_inverse(I.midpoint(*J))
    w = (F[1] - F[0]).reshape(R * m, n)
    return np.einsum("rij,rj->r", np.abs(C), w).reshape(R, m)


def _bisect(xi_lo, xi_hi, full_w, spread=None):
    """Halve each geometry sub-box ``(R, m)`` along the parameter whose width spreads the pose most
    (``spread`` ``(R, m)``, :func:`_pose_spread`), or, where that is not finite or not given, the one widest
    relative to the calibration box (widths ``full_w`` ``(m,)``); the two halves share the float split
    point, so they cover the parent."""
    rel = np.where(full_w > 0, (xi_hi - xi_lo) / np.where(full_w > 0, full_w, 1.0), 0.0)
    if spread is not None:
        ok = np.all(np.isfinite(spread), axis=1) & np.any(spread > 0, axis=1)
        rel = np.where(ok[:, None] & (xi_hi > xi_lo), np.where(np.isfinite(spread), spread, 0.0), rel)
    axis = np.argmax(rel, axis=1)
    rows = np.arange(len(axis))
    mid = 0.5 * (xi_lo[rows, axis] + xi_hi[rows, axis])
    left_hi = xi_hi.copy()
    left_hi[rows, axis] = mid
    right_lo = xi_lo.copy()
    right_lo[rows, axis] = mid
    return np.concatenate([xi_lo, right_lo]), np.concatenate([left_hi, xi_hi])


class Hypothesis:
    """The rows (geometry sub-boxes with their tubes) under "the last pose is in mode ``m``".

    A row is dropped once its tubes become empty or certify another mode at
    an end of the recording; the hypothesis is refuted when no row is left.
    """

    def __init__(self, finals, xlo, xhi, tx, txd, m0, m):
        self.finals, self.m0, self.m = finals, m0, m
        self.xlo, self.xhi, self.tx, self.txd = xlo, xhi, tx, txd
        self.passes = 0
        self.refutation = Refutation.NONE
        self.complete = True  # False once the rounds stopped before this hypothesis used its budget
        self.extra = 0  # rounds run after one-motion steps without halving (ONE_MOTION_ROUNDS)
        self.asked = False  # offered to the explainer (once, when its budget of sub-boxes is spent)
        self.explained = False  # the explainer answered EXPLAINED: no more rounds
        self.kept = set()  # sub-boxes (bytes of lo, hi) a one-motion step left as they were
        self._final_boxes()

    @property
    def refuted(self) -> bool:
        return self.refutation is not Refutation.NONE

    def _keep(self, live):
        self.xlo, self.xhi, self.tx, self.txd = self.xlo[live], self.xhi[live], self.tx[live], self.txd[live]
        self.final = self.final[live]

    def _final_boxes(self):
        self.final, ok = self.finals.of(self.xlo, self.xhi, self.m)
        self.xlo, self.xhi, self.tx, self.txd = self.xlo[ok], self.xhi[ok], self.tx[ok], self.txd[ok]
        if not ok.any():
            self.refutation = Refutation.NO_SOLUTION if self.passes == 0 else Refutation.EMPTY_TUBE

    def starts(self, backward):
        """Initial boxes ``(R, n)`` of a pass: the final box within the tube's last box (backward), or the
        tube's first box (forward)."""
        if backward:
            end = self.tx[:, -1]
            return np.maximum(self.final[:, 0], end[:, 0]), np.minimum(self.final[:, 1], end[:, 1])
        return self.tx[:, 0, 0], self.tx[:, 0, 1]

    def take(self, x, xd, md, bad, xi, times=None):
        """The tubes and contracted calibration sub-boxes ``xi`` (``(lo, hi)`` ``(R, m)``) of a pass over this
        hypothesis' rows (forward time); drop the rows it refutes.  ``times``: the samples' time enclosures
        ``(K, 2)`` of an uneven recording (s), None for steps of ``t_s``."""
        self.passes += 1
        last, first = md[:, -1], md[:, 0]
        other = ((last != 0) & (last != self.m)) | ((first != 0) & (first != self.m0))
        s = self.finals.s
        # empty tubes, or tubes no motion within a_max fits (contracted between samples: step 8)
        dead = (bad >= 0) | contract_tubes(x, xd, s.t_s, s.a_max, compiled=self.finals.backend == Backend.COMPILED,
                                           times=times)
        live = ~dead & ~other
        self.tx, self.txd = x, xd
        # the pass started from these sub-boxes and only contracted them; intersecting is exact and keeps
        # a row's sub-box inside its parent's whatever the kernel holds
        self.xlo, self.xhi = np.maximum(self.xlo, xi[0]), np.minimum(self.xhi, xi[1])
        live &= np.all(self.xlo <= self.xhi, axis=1)  # no geometry of the sub-box fits every sample
        if not live.any():
            self.refutation = Refutation.EMPTY_TUBE if np.all(dead) else Refutation.OTHER_MODE
        self._keep(live)

    def one_motion(self, q, samples) -> bool:
        """Drop the rows that no single geometry of their sub-box and single motion in their tubes explain
        over ``samples`` samples of the readings ``q``, and narrow the others' sub-boxes to the geometries
        that can (:func:`verifier.one_motion.one_motion_rows`).  True when a row was dropped or a sub-box
        narrowed by at least :data:`ONE_MOTION_SHRINK` along some parameter (another round may then decide
        more).  A row whose sub-box a step left as it was is not asked again while its sub-box stays the same
        (only its tubes changed, by the passes it already survived): on certify's plans 148 such rows asked
        again were never dropped and one was narrowed, by under a tenth; a row not asked is only kept, which
        is always sound (docs/tracker.md)."""
        keys = [lo.tobytes() + hi.tobytes() for lo, hi in zip(self.xlo, self.xhi)]
        ask = np.array([k not in self.kept for k in keys], dtype=bool)
        out, lo, hi = np.zeros(len(keys), dtype=bool), self.xlo.copy(), self.xhi.copy()
        if ask.any():
            out[ask], lo[ask], hi[ask] = one_motion_rows(self.finals.model, self.finals.s, q,
                                                         (self.xlo[ask], self.xhi[ask]), self.tx[ask], self.txd[ask],
                                                         samples, compiled=self.finals.backend == Backend.COMPILED)
        same = ask & ~out & np.all(lo == self.xlo, axis=1) & np.all(hi == self.xhi, axis=1)
        self.kept.update(k for k, s in zip(keys, same) if s)
        w0 = self.xhi - self.xlo
        # the proved bounds only narrow: intersecting is exact and keeps each sub-box inside its own
        self.xlo, self.xhi = np.maximum(self.xlo, lo), np.minimum(self.xhi, hi)
        live = ~out & np.all(self.xlo <= self.xhi, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            narrowed = np.any((self.xhi - self.xlo) < (1.0 - ONE_MOTION_SHRINK) * w0, axis=1)
        changed = bool(np.any(~live) or np.any(narrowed[live]))
        if not live.any():
            self.refutation = Refutation.ONE_MOTION
        self._keep(live)
        return changed

    def split(self, full_w, q_first):
        """Halve every surviving geometry sub-box along the parameter that spreads the pose most at the two
        ends of the recording (first reading ``q_first``); children start from their parent's tubes."""
        model = self.finals.model
        R, n = len(self.xlo), model.n
        # both ends in one evaluation of the tapes (their numpy cost is per call, not per row)
        q_ends = np.concatenate([np.broadcast_to(np.asarray(q_first, dtype=np.float64), (R, n)),
                                 np.broadcast_to(np.asarray(self.finals.q_last, dtype=np.float64), (R, n))])
        with I.quiet_fp():
            both = _pose_spread(model, np.concatenate([self.tx[:, 0], self.tx[:, -1]]), q_ends,
                                np.concatenate([self.xlo, self.xlo]), np.concatenate([self.xhi, self.xhi]),
                                compiled=self.finals.backend == Backend.COMPILED)
            spread = both[:R] + both[R:]
        self.xlo, self.xhi = _bisect(self.xlo, self.xhi, full_w, spread)
        self.tx, self.txd = np.concatenate([self.tx, self.tx]), np.concatenate([self.txd, self.txd])
        self._final_boxes()

    def result(self) -> HypothesisResult:
        if self.refuted:
            return HypothesisResult(self.m, HypothesisStatus.REFUTED, self.refutation, self.passes, 0)
        status = HypothesisStatus.EXPLAINED if self.explained else HypothesisStatus.CONSISTENT
        return HypothesisResult(self.m, status, self.refutation, self.passes, len(self.xlo),
                                self.complete, *tube_hull(self.tx, self.txd), self.xlo, self.xhi)


def _round(h, passes, max_passes, rel_tol):
    """One round of ``h``: backward and forward passes alternate until one shrinks its tubes by less than
    ``rel_tol`` (after at least two), ``max_passes``, or the hypothesis is refuted."""
    if h.refuted:  # no row left since its last halving
        return
    width = _width(h.tx, h.txd)
    for p in range(1, max_passes + 1):
        passes.run(h, backward=bool(p % 2))
        if h.refuted:
            return
        new = _width(h.tx, h.txd)
        if p >= 2 and not new < (1.0 - rel_tol) * width:
            return
        width = new


def decide(hyps, passes, max_passes, rel_tol, max_geometries, full_w, targets=None, one_motion=0, ask=None):
    """Rounds on the hypotheses ``targets`` (all of ``hyps`` by default), halving each one's geometries
    after each of its rounds while they stay within ``max_geometries``, until a hypothesis is refuted or
    none can be halved.

    The next round goes to the hypothesis that has run the fewest rows so far (the initial mode's first).
    Under valid assumptions the true hypothesis is never refuted, and each hypothesis' rounds do not
    depend on the other's: the verdict does not depend on this order, while the cost does.  A false
    hypothesis loses rows at every round; the true one keeps them all and costs the most.  Balancing the
    rows run bounds the work by about twice what the false hypothesis needs to be refuted (up to one
    round of the other), where taking the hypotheses level by level spends the true one's rounds at
    every level.

    The rounds stop at the first refutation: the other hypothesis is then left as it stands, consistent
    but marked incomplete (``HypothesisResult.complete``), since its skipped rounds might have refuted
    it too (the recording would then be ``inconsistent``).  Running them would cost the surviving
    hypothesis' rounds on every decided recording, and a refuted hypothesis is false whatever the
    other one's tubes are (measured: benchmarks/README.md's git history).  A hypothesis left out of ``targets``
    runs no round and is marked incomplete too.

    ``ask`` (``ask(h) -> Explanation``, optional) is called once per hypothesis, when its budget of
    sub-boxes is spent and before its one-motion step (so a recording decided within the budget never
    calls it).  An explained hypothesis leaves the rounds (complete: no sound pass can refute a
    hypothesis an admissible motion satisfies); once every hypothesis of ``targets`` is explained the
    rounds stop.  Trusting a wrong answer only keeps a false hypothesis alive: ``unknown``, never a
    wrong verdict.
    """
    open_ = list(hyps if targets is None else targets)
    for h in hyps:
        if h not in open_:
            h.complete = h.refuted
    rows = [0] * len(open_)
    while open_:
        i = min(range(len(open_)), key=rows.__getitem__)  # ties: the first, the initial mode's
        h = open_[i]
        before = passes.rows
        _round(h, passes, max_passes, rel_tol)
        rows[i] += passes.rows - before
        if ask is not None and not h.refuted and not h.asked and 2 * len(h.xlo) > max_geometries:
            h.asked = True
            h.explained = Explanation(ask(h)) is Explanation.EXPLAINED
            if h.explained:
                del open_[i], rows[i]
                if all(t.explained for t in (hyps if targets is None else targets)):
                    return  # no sound method can decide: stop (unknown)
                continue
        if one_motion and not h.refuted and 2 * len(h.xlo) > max_geometries:
            # the budget is spent: the one-motion step is the last resort; the rows it drops give the halving
            # room again, and the sub-boxes it narrows tighten the next round's tubes
            changed = h.one_motion(passes.q, one_motion)
            if changed and not h.refuted and 2 * len(h.xlo) > max_geometries and h.extra < ONE_MOTION_ROUNDS:
                h.extra += 1
                continue  # another round with the narrowed sub-boxes, no halving
        if not h.refuted and 2 * len(h.xlo) <= max_geometries:
            h.split(full_w, passes.q[0])  # may refute it: no child has a final box
        elif not h.refuted:
            del open_[i], rows[i]  # its budget is spent: it stays consistent and complete
            continue
        if h.refuted:
            for other in open_:
                other.complete = other.refuted
            return
