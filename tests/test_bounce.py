"""The gap for mode-unchanged (planner.bounce): bounces certified only beyond the crossing floor."""

from __future__ import annotations

from crosscert.planner.bounce import bounce_gap
from crosscert.planner.task import PlanningBounds
from crosscert.robots import DEXTAR
from crosscert.verifier.tracker import Verdict


def test_bounces_are_certified_only_beyond_the_crossing_floor(task, kin, imodel):
    """On the benchmark task at 1.2 m/s: a crossing explains the bounces turning back up to the floor
    (~10 mm), the tracker never certifies mode-unchanged at or inside it, never mode-changed anywhere,
    and certifies the bounces that turn back far enough."""
    g = bounce_gap(DEXTAR, task, PlanningBounds(), 1.2, distances=(0.0, 0.004, 0.009, 0.012, 0.02), tol=1e-3,
                   kin=kin, imodel=imodel, exhaustive=True)
    assert g.floor is not None and 0.005 < g.floor < 0.015, g.summary()
    assert all(v is not Verdict.MODE_CHANGED for v in g.verdicts), g.summary()
    for d, v in zip(g.distances, g.verdicts):
        if d <= g.floor:
            assert v is not Verdict.MODE_UNCHANGED, (d, g.summary())
    assert g.certified_from is not None and g.certified_from > g.floor, g.summary()
    assert g.verdicts[-1] is Verdict.MODE_UNCHANGED
    s = g.summary()
    assert s["gap_m"] == g.certified_from - g.floor and len(s["tracker"]) == 5


def test_bounces_assume_the_bounds_they_are_given(task, kin, imodel, monkeypatch):
    """The tracker's side and the crossing searches of the bounces read ``a_max`` and ``xd0`` from the
    bounds (a certification passes its own, for its plan), not from the robot."""
    from crosscert.planner import bounce

    b = PlanningBounds(a_max=(100.0, 90.0), xd0=(0.3, 0.2)).resolve(DEXTAR)
    seen = {}

    class Stop(Exception):
        pass

    def window(_model, _q, settings, **_kw):
        seen["settings"] = settings
        raise Stop

    monkeypatch.setattr(bounce, "track_window", window)
    try:
        bounce.bounce_verdicts(DEXTAR, task, b, 1.1, distances=(0.03,), kin=kin, imodel=imodel)
    except Stop:
        pass
    s = seen["settings"]
    assert s.assumptions is b.assumptions
    assert s.a_max.tolist() == [100.0, 90.0] and s.xd0.tolist() == [0.3, 0.2]
    floor = bounce._floor_bounds(b)
    assert floor["a_max"].tolist() == [100.0, 90.0] and floor["v0_max"].tolist() == [0.3, 0.2]
