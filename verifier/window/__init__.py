"""Window reasoning: the whole recording as one constraint network, contracted
forward and backward in time, split on the final assembly mode.

The tracker (:mod:`verifier.step`) is a forward filter: the boxes of sample
``k`` use the readings up to ``k`` only.  A verdict given at the end of a
recording may use every reading.  :func:`track_window` does so:

1. **Tubes per geometry hypothesis.**  The calibration box is partitioned as
   the tracker does (``settings.xi_splits``); each sub-box ``p`` gets its own
   pose and velocity tubes ``[x]_k^p``, ``[xd]_k^p``, ``k = 0..K-1``.  The true
   geometry is one constant vector, so it lies in one sub-box for the whole
   recording: a sub-box refuted in any pass is refuted for good.
2. **Hypotheses on the final mode.**  For ``m`` in {+1, -1}: "the true pose at
   the last sample is in assembly mode ``m``".  Under it, the last pose lies
   in the hull of the forward-kinematics solutions of the last reading whose
   mode is ``m`` or undecided.
3. **Passes.**  A forward pass is the tracker with every sample's boxes
   intersected with the tubes (``verifier.step.advance(prior=...)``); a
   backward pass is the tracker on the time-reversed recording (readings
   ``q_{K-1-k}``, velocity ``-xd``, the same acceleration and reading-error
   bounds, which are symmetric in time), started from the final box of the
   hypothesis and intersected with the tubes.  Passes alternate, backward
   first, until the tubes stop shrinking or a hypothesis is refuted.
4. **Refutation.**  A sub-box whose tubes become empty is refuted; so is one
   whose boxes certify, at the last sample, a mode other than ``m`` (or, at
   the first, other than the initial one).  A hypothesis with every sub-box
   refuted is refuted.  The verdict is certified when exactly one hypothesis
   survives; both refuted means an assumption was violated (``inconsistent``).
5.  **One motion, one geometry.**  When a hypothesis' budget of sub-boxes is
    spent, each of its rows is tested as one constant geometry and one motion
    over the samples around its widest pose box (:mod:`verifier.one_motion`,
    a linear relaxation whose infeasibility is proved by a Farkas certificate);
    the rows proved impossible are dropped, which frees budget for halving,
    and the others' sub-boxes narrowed to the geometries the relaxation
    allows (proved bounds by weak duality); a step that changed something
    earns another round of passes with the narrowed sub-boxes.
6.  **Early stop when no sound method can decide.**  With an
    :class:`Explainer` (the planner's counterexample searches), a hypothesis
    that spent its budget of sub-boxes is offered to it before the one-motion
    step: when it answers :attr:`Explanation.EXPLAINED` (a verified
    admissible motion ending in that mode explains every reading) the
    hypothesis runs no more rounds, and once every hypothesis asked about is
    explained the window stops with ``unknown``
    (:attr:`VerdictReason.UNDECIDABLE`).  Stopping only ever gives
    ``unknown``; a wrong explainer can turn a verdict into ``unknown`` and
    nothing else.

Every pass only removes what cannot hold under the tracker's assumptions and
the hypothesis, so a refuted hypothesis is false (docs/soundness.md, "Window
reasoning").  Shapes: ``K`` samples, pose dimension ``n``; SI units.

Modules: :mod:`.results` (what a window reports), :mod:`.explain` (the
:class:`Explainer` protocol), :mod:`.passes` (one pass over the rows, the
final boxes), :mod:`.hypotheses` (the rounds, halving and one-motion step of
each hypothesis), :mod:`.offline` (:func:`track_window`, which may start
from a tracker's state, :class:`WindowStart`) and :mod:`.online`
(:class:`OnlineMonitor`: the tracker, and a window anchored at the last
sample whose mode it knew, while the robot moves).  Explicit re-exports (no
star imports).
"""

from .explain import Explainer, ExplainRequest, Explanation
from .offline import WINDOW_MAX_GEOMETRIES, WINDOW_MAX_PASSES, WindowStart, track_window
from .online import ONLINE_HORIZON, OnlineMonitor, online_boxes
from .results import (HypothesisResult, HypothesisStatus, OnlineEvent, OnlineResult, Reasoning, Refutation,
                      VerdictReason, WindowResult, WindowState)

__all__ = ["Reasoning", "HypothesisStatus", "Refutation", "HypothesisResult", "WindowResult", "track_window",
           "WindowStart", "OnlineMonitor", "OnlineResult", "OnlineEvent", "WindowState", "ONLINE_HORIZON", "online_boxes",
           "WINDOW_MAX_PASSES", "WINDOW_MAX_GEOMETRIES", "VerdictReason", "Explanation", "ExplainRequest",
           "Explainer"]
