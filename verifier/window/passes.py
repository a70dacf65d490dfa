"""One pass of the window over its rows (geometry sub-boxes with their tubes), and the boxes it starts from.

A pass is one ``advance`` call over the readings for every row of a
hypothesis (:func:`run_pass`, :class:`Passes`); a backward pass runs on the
time-reversed recording.  The final boxes are the hulls of a reading's pose
solutions of one mode (:func:`reading_solutions`, :func:`hull_of_mode`,
:class:`FinalBoxes`).  Shapes: ``R`` rows, ``K`` samples, pose dimension
``n``, ``m`` geometry parameters; SI units.
"""

from __future__ import annotations

import numpy as np

from ..step import advance, init_state, pose_solution_arrays, reading_box

__all__ = ["run_pass", "tube_hull", "reading_solutions", "hull_of_mode", "FinalBoxes", "Passes"]


def _reverse(x, xd):
    """Tubes ``(R, K, 2, n)`` of a motion, as tubes of the time-reversed motion (velocity negated)."""
    xr = x[:, ::-1]
    xdr = -xd[:, ::-1, ::-1]  # [-hi, -lo]: negation is exact
    return np.ascontiguousarray(xr), np.ascontiguousarray(xdr)


def run_pass(config, q, x0, xi_rows, prior, clock=None):
    """One pass over readings ``q`` ``(K, n)`` for rows ``R``: tubes ``(R, K, 2, n)``, modes ``(R, K)``, death
    ``(R,)`` and the rows' calibration sub-boxes ``(lo, hi)`` ``(R, m)`` at the end of the pass (contracted by
    every sample's loop closure when ``config`` keeps them, ``keep_xi``; meaningless for a dead row); ``clock``
    the samples' uneven times (:mod:`verifier.clock`), None for steps of ``t_s``."""
    lo, hi = xi_rows
    R, (K, n) = lo.shape[0], q.shape
    st = init_state(config, x0, batch=R, xi_box=(lo, hi))
    rec = (np.empty((R, K, 2, n)), np.empty((R, K, 2, n)), np.empty((R, K), np.int64), np.empty((R, K, n)))
    advance(config, st, np.broadcast_to(q, (R, K, n)), rec, prior, clock)
    return rec[0], rec[1], rec[2], st.bad_at.copy(), (st.xi[:, 0].copy(), st.xi[:, 1].copy())


def tube_hull(x, xd):
    """Hull over the rows of tubes ``(R, K, 2, n)``: ``x_lo, x_hi, xd_lo, xd_hi`` ``(K, n)``."""
    return x[:, :, 0].min(0), x[:, :, 1].max(0), xd[:, :, 0].min(0), xd[:, :, 1].max(0)


def _search_box(model, search):
    """The box known to hold the last pose: ``search`` or the robot's ``x_bounds``."""
    if search is None:
        search = model.robot.x_bounds
    return np.asarray(search[0], dtype=np.float64), np.asarray(search[1], dtype=np.float64)


def reading_solutions(model, q_last, s, xi_row, backend, search, tol):
    """Pose solutions of the last reading ``q_last`` (rad, widened by ``eps_q``) for the geometry sub-box
    ``xi_row`` inside ``search``: boxes ``(N, 2, n)`` (m) and their modes ``(N,)`` (0: undecided), or
    ``None`` when the enumeration gave up.  One enumeration serves both final-mode hypotheses."""
    return pose_solution_arrays(model, reading_box(q_last, s.eps_q), xi_row, search, tol=tol, backend=backend)


def hull_of_mode(sols, mode, search):
    """Hull ``(2, n)`` of the solution boxes of mode ``mode`` or undecided; ``None`` when there is none;
    the search box when the solutions were not isolated (``sols`` is ``None``)."""
    if sols is None:
        return np.stack(search)
    boxes, modes = sols
    # undecided boxes stay: a pose on the singular locus is the limit of both modes
    mine = boxes[(modes == mode) | (modes == 0)]
    if not len(mine):
        return None
    return np.stack([mine[:, 0].min(0), mine[:, 1].max(0)])


def _final_box(model, q_last, mode, s, xi_row, backend, search=None, tol=1e-5):
    """Hull ``(2, n)`` of the pose solutions of the last reading in mode ``mode`` or undecided, inside
    ``search`` (the robot's ``x_bounds`` by default; any box known to hold the pose), ``None`` when there
    is none (the geometry cannot end in that mode), the search box when they could not be isolated."""
    search = _search_box(model, search)
    return hull_of_mode(reading_solutions(model, q_last, s, xi_row, backend, search, tol), mode, search)


class FinalBoxes:
    """Final boxes of geometry sub-boxes, enumerated once per sub-box and shared by both hypotheses
    (they start from the same sub-boxes, and a halved sub-box is often alive under both): inside
    ``search`` (a box known to hold the last pose; the robot's ``x_bounds`` by default), to the
    resolution ``tol`` (m)."""

    def __init__(self, model, q_last, s, backend, search=None, tol=1e-5):
        self.model, self.q_last, self.s, self.backend, self.tol = model, q_last, s, backend, tol
        self.search = _search_box(model, search)
        self.cache = {}

    def of(self, xlo, xhi, mode):
        """Final boxes ``(R, 2, n)`` of the rows ``xlo, xhi`` ``(R, m)`` under ``mode``, and which rows have one."""
        boxes, ok = [], np.zeros(len(xlo), dtype=bool)
        for i, (lo, hi) in enumerate(zip(xlo, xhi)):
            key = lo.tobytes() + hi.tobytes()
            if key not in self.cache:
                self.cache[key] = reading_solutions(self.model, self.q_last, self.s, (lo, hi), self.backend,
                                                    self.search, self.tol)
            box = hull_of_mode(self.cache[key], mode, self.search)
            if box is not None:
                ok[i] = True
                boxes.append(box)
        return (np.stack(boxes) if boxes else np.empty((0, 2, self.model.n))), ok


class Passes:
    """The passes of the window: one ``advance`` call per pass over a hypothesis' rows, spread over the
    threads (each row is its own scenario: the rows batched with it change none of its boxes)."""

    def __init__(self, q, cfg_f, cfg_b, clock=None):
        self.q, self.cfg_f, self.cfg_b = q, cfg_f, cfg_b
        self.q_rev = np.ascontiguousarray(q[::-1])
        # an uneven recording's times: forward, reversed for the backward passes, and the samples' enclosures
        self.clock, self.clock_rev = clock, None if clock is None else clock.window(0, reverse=True)
        self.times = None if clock is None else clock.times()
        self.rows = 0  # rows run by every pass so far: the cost :func:`~verifier.window.hypotheses.decide` balances

    def run(self, h, backward):
        """One pass over the rows of hypothesis ``h``, which takes its tubes."""
        x0, xi = h.starts(backward), (h.xlo, h.xhi)
        self.rows += len(h.xlo)
        if backward:
            x, xd, md, bad, xi = run_pass(self.cfg_b, self.q_rev, x0, xi, _reverse(h.tx, h.txd), self.clock_rev)
            x, xd = _reverse(x, xd)
            md = md[:, ::-1]
        else:
            x, xd, md, bad, xi = run_pass(self.cfg_f, self.q, x0, xi, (h.tx, h.txd), self.clock)
        h.take(x, xd, md, bad, xi, self.times)
