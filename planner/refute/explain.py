"""The window's explainer: a verified counterexample search for one final-mode hypothesis.

:func:`verifier.window.track_window` asks an :class:`~verifier.window.Explainer`
about a hypothesis ("the last pose is in mode ``m``") once the hypothesis has
spent its budget of geometry sub-boxes.  :class:`RefutingExplainer` answers with
the searches of this package: a bounce (:func:`search_bounce`, mode ``m0`` at
every sample) when ``m`` is the initial mode ``m0``, a crossing
(:func:`search_crossing`, ``m0`` first, ``-m0`` last) otherwise, seeded with
the hypothesis' surviving geometry sub-boxes.  ``EXPLAINED`` is answered only
for a candidate the trusted check (:mod:`.verify`) accepted against bounds
built from the window's own settings and calibration box, and inside the
window's initial box when it has one.

What the check covers, and therefore which settings this explainer answers
for: the reading error ``eps_q`` at every sample, ``|x''| <= a_max``
(piecewise-constant accelerations), the initial speed bound ``xd0``, the speed
bound ``v_max``, the calibration box, the robot's workspace box, the modes.
Not covered, so answered ``NOT_COVERED`` (no claim): a drift model of the
reading error (``eps_q_fast``, ``drift_rate``: the search treats readings as
erring independently) and a user-given joint-acceleration bound
(``TrackerSettings.qdd_bound``).  The check is numerical (floating point, with
the NLP's margins, IK continuation at finitely many points), not an interval
proof: the window uses the answer only to stop with ``unknown``
(docs/soundness.md, "Early stop").  SI units.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from crosscert.robots.errors import InputError, SimulationError
from crosscert.verifier.window import ExplainRequest, Explanation

from ..models import kinematic_model
from .nlp import MAX_ITER, nlp_variables, scaled_cpu_time, search_counterexample
from .problem import CounterexampleKind, RecordingBounds
from .results import BounceSearch
from .verify import DENSE_POINTS

__all__ = ["EXPLAIN_CPU_TIME", "EXPLAIN_MAX_VARIABLES", "EXPLAIN_STARTS", "ExplainAttempt", "RefutingExplainer"]

#: IPOPT CPU cap per search of the explainer, s (scaled up above :data:`EXPLAIN_CAP_VARIABLES` unknowns): a
#: search that stops proves nothing, the window then goes on as without an explainer.
EXPLAIN_CPU_TIME = 2.0
#: NLP size (unknowns) that gets :data:`EXPLAIN_CPU_TIME` as it is.
EXPLAIN_CAP_VARIABLES = 4000
#: Surviving sub-boxes whose centres seed a search, at most (each one a separate IPOPT solve).
EXPLAIN_STARTS = 2
#: Largest NLP (unknowns) the explainer searches (the two-joint benchmark's 1.0 m/s crossings: 2053).  Beyond,
#: the searches cost more than the rounds they can save: on the 3-RPR's 546-sample bounce (6912 unknowns,
#: 2026-12-03) `check` took 150 s with them (IPOPT 18 s, the rest building the NLPs and the three-joint
#: forward-kinematics guesses) against 42 s without.
EXPLAIN_MAX_VARIABLES = 4000


@dataclass(frozen=True, eq=False)
class ExplainAttempt:
    """One question of a window to :class:`RefutingExplainer` and its answer.

    Attributes
    ----------
    final_mode : int
        The hypothesis asked about (+1 / -1).
    kind : CounterexampleKind or None
        The search run (``None``: none, the settings are not covered).
    outcome : Explanation
    searches : tuple of BounceSearch
        The IPOPT solves, in order (the last one decided).
    solve_s : float
        IPOPT wall time over the searches, s.
    wall_s : float
        Wall time of the whole answer (bounds, seeds, solves, checks), s.
    """

    final_mode: int
    kind: CounterexampleKind | None
    outcome: Explanation
    searches: tuple
    solve_s: float
    wall_s: float


def _seeds(request: ExplainRequest, starts: int) -> list:
    """Centres of up to ``starts`` surviving sub-boxes, spread over their list (the first, then evenly)."""
    R = request.xi_lo.shape[0]
    if R == 0:
        return [None]
    idx = sorted({int(i) for i in np.linspace(0, R - 1, min(starts, R)).round()})
    return [0.5 * (request.xi_lo[i] + request.xi_hi[i]) for i in idx]


class RefutingExplainer:
    """:class:`~verifier.window.Explainer` by verified counterexample search (module docstring).

    Parameters
    ----------
    starts : int
        Seeds tried per hypothesis, at most (:data:`EXPLAIN_STARTS`).
    max_cpu_time : float
        IPOPT CPU cap per search, s (scaled for large NLPs).
    dense : int
        IK continuation points per interval of the check.
    max_variables : int
        Largest NLP (unknowns) searched; larger ones are answered ``not-searched``.

    Attributes
    ----------
    log : list of ExplainAttempt
        Every answer given, in order (what the searches cost).
    """

    def __init__(self, *, starts: int = EXPLAIN_STARTS, max_cpu_time: float = EXPLAIN_CPU_TIME,
                 dense: int = DENSE_POINTS, max_variables: int = EXPLAIN_MAX_VARIABLES):
        if isinstance(starts, bool) or int(starts) != starts or starts < 1:
            raise InputError(f"starts must be a positive integer, got {starts!r}")
        if not max_cpu_time > 0:
            raise InputError(f"max_cpu_time must be positive, s; got {max_cpu_time!r}")
        self.starts, self.max_cpu_time, self.dense = int(starts), float(max_cpu_time), int(dense)
        self.max_variables = int(max_variables)
        self.log: list[ExplainAttempt] = []

    def __call__(self, request: ExplainRequest) -> Explanation:
        t0 = time.perf_counter()
        outcome, kind, searches = self._answer(request)
        self.log.append(ExplainAttempt(int(request.final_mode), kind, outcome, tuple(searches),
                                       float(sum(s.solve_time for s in searches)), time.perf_counter() - t0))
        return outcome

    def _answer(self, request: ExplainRequest):
        s = request.settings
        a = s.assumptions
        # assumptions the search and its check do not model: no claim
        if a.drift is not None or s.qdd_bound is not None or request.q.shape[0] < 2:
            return Explanation.NOT_COVERED, None, []
        kin = kinematic_model(request.model.robot)
        size = nlp_variables(kin, request.q.shape[0])
        if size > self.max_variables:
            return Explanation.NOT_SEARCHED, None, []
        kind = CounterexampleKind.BOUNCE if request.final_mode == request.initial_mode else CounterexampleKind.CROSSING
        xi_lo, xi_hi = (np.asarray(v, dtype=np.float64) for v in request.xi_box)
        # the window's own bounds: its settings' assumptions with its calibration box, the robot's workspace box
        rb = RecordingBounds.for_model(kin, request.q, m0=int(request.initial_mode),
                                       assumptions=a.with_(xi_box=(xi_lo, xi_hi)))
        cpu = scaled_cpu_time(self.max_cpu_time, size, EXPLAIN_CAP_VARIABLES)
        searches: list[BounceSearch] = []
        for seed in _seeds(request, self.starts):
            if seed is not None:
                seed = np.clip(seed, xi_lo, xi_hi)
            try:
                att = search_counterexample(kin, rb, kind, xi_start=seed, max_iter=MAX_ITER, max_cpu_time=cpu,
                                            dense=self.dense)
            except SimulationError:  # no pose of the mode(s) for this seed: try the next one
                continue
            searches.append(att)
            if att.verified and self._in_initial_box(att, request):
                return Explanation.EXPLAINED, kind, searches
        return Explanation.NOT_FOUND, kind, searches

    @staticmethod
    def _in_initial_box(att: BounceSearch, request: ExplainRequest) -> bool:
        """The witness' first pose lies in the window's initial box (always, when it was given the mode)."""
        if request.x0 is None:
            return True
        x = att.counterexample.x[0]
        return bool(np.all(x >= request.x0[0]) and np.all(x <= request.x0[1]))
