"""The one owner of the assumptions: one rule per field, checked once, immutable, read by every holder."""

import dataclasses

import numpy as np
import pytest

from crosscert.planner.refute.problem import RecordingBounds
from crosscert.planner.task import PlanningBounds, resolved
from crosscert.robots import DEXTAR, RPR3, InputError, ModelError
from crosscert.robots.assumptions import RULES, Assumptions, check_bound
from crosscert.verifier.settings import TrackerSettings

GOOD = dict(t_s=1e-3, eps_q=1e-4, a_max=(80.0, 80.0), n=2)


@pytest.mark.parametrize("field, value, message", [
    ("eps_q", 0.0, "reading error eps_q must be positive and finite, in each joint.s unit"),
    ("eps_q", (1e-4, -1e-4), "eps_q must be positive"),
    ("eps_q", np.inf, "eps_q must be positive and finite"),
    ("t_s", 0.0, "t_s must be positive and finite"),
    ("t_s", float("nan"), "t_s must be positive and finite"),
    ("t_s", True, "t_s must be positive"),
    ("a_max", (80.0, 0.0), "a_max must be positive and finite, in each axis. unit/s\\^2"),
    ("a_max", (80.0, 80.0, 80.0), "a_max needs 1 or 2 entries"),
    ("a_max", (80.0, np.inf), "a_max must be positive and finite"),
    ("xd0", -0.1, "xd0 must be non-negative"),
    ("v_max", 0.0, "v_max must be positive"),
    ("xi_box", ((0.0, 1.0), (1.0, 0.0)), "calibration box is empty"),
    ("xi_box", ((0.0,), (1.0, 2.0)), "one length"),
    ("drift", (1e-5, None), "give both or neither"),
    ("drift", (-1e-5, 1.0), "eps_q_fast must be non-negative"),
])
def test_each_rule_refuses_what_its_field_cannot_be(field, value, message):
    with pytest.raises(InputError, match=message):
        Assumptions(**{**GOOD, field: value})


def test_every_field_has_one_rule():
    """The rules are the fields' (no field unchecked, no stray rule)."""
    stored = {f.name for f in dataclasses.fields(Assumptions)} - {"joint_units", "pose_units", "n"}
    assert set(RULES) == stored


def test_units_in_messages_are_the_robots_own():
    """eps_q of a prismatic joint is in m; a_max of a mixed pose names each axis' unit."""
    with pytest.raises(InputError, match=r"eps_q must be positive and finite, in m;"):
        Assumptions.for_robot(RPR3, eps_q=0.0)
    with pytest.raises(InputError, match=r"in \(m/s\^2, m/s\^2, rad/s\^2\)"):
        Assumptions.for_robot(RPR3, a_max=-1.0)
    a = RPR3.assumptions
    assert a.unit("eps_q") == "m" and a.unit("xd0") == "(m/s, m/s, rad/s)" and DEXTAR.assumptions.unit("eps_q") == "rad"


def test_values_are_normalised_and_immutable():
    a = Assumptions(**GOOD)
    assert a.n == 2 and a.eps_q.tolist() == [1e-4, 1e-4]
    assert np.all(np.isinf(a.xd0)) and np.all(np.isinf(a.v_max)) and a.drift is None
    for arr in (a.eps_q, a.a_max, a.xd0, a.v_max):
        with pytest.raises(ValueError):
            arr[0] = 0.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.t_s = 1.0
    assert a.with_(xd0=0.0).xd0.tolist() == [0.0, 0.0]  # at rest is a state, not a degenerate bound


def test_robot_defaults_obey_the_same_rules():
    with pytest.raises(ModelError, match="Robot dextar: reading error eps_q must be positive"):
        dataclasses.replace(DEXTAR, eps_q=0.0)
    assert check_bound("t_s", 1e-3) == 1e-3 and check_bound("eps_q", 2e-5) == 2e-5


def test_tracker_settings_hold_one_value_checked_once():
    """eps_q = 0 is refused by TrackerSettings like everywhere else; its old names read the value; a copy with
    another option keeps the very same value (not checked again); a copy with xd0=None has no initial bound."""
    with pytest.raises(InputError, match="eps_q must be positive"):
        TrackerSettings(t_s=1e-3, eps_q=0.0, a_max=(80.0, 80.0))
    s = TrackerSettings.for_robot(DEXTAR, eps_q=2e-4, eps_q_fast=1e-4, drift_rate=0.5)
    assert s.eps_q.tolist() == [2e-4, 2e-4] and s.t_s == DEXTAR.t_s and s.drift_rate.tolist() == [0.5, 0.5]
    assert s.validated(2) is s
    assert dataclasses.replace(s, xi_splits=None).assumptions is s.assumptions
    free = dataclasses.replace(s, xd0=None)
    assert np.all(np.isinf(free.xd0)) and free.eps_q_fast.tolist() == [1e-4, 1e-4]
    with pytest.raises(InputError, match="2 coordinates, the model has 3"):
        s.validated(3)


def test_recording_and_planning_bounds_use_the_same_rules():
    q = np.zeros((3, 2))
    rb = RecordingBounds(q_meas=q, m0=1, t_s=1e-3, eps_q=1e-4, a_max=80.0, xi_lo=(0.0,), xi_hi=(1.0,))
    assert rb.v0_max is None and rb.a_max.tolist() == [80.0, 80.0]
    assert dataclasses.replace(rb, eps_q=2e-4).eps_q.tolist() == [2e-4, 2e-4]
    with pytest.raises(InputError, match="eps_q must be positive"):
        dataclasses.replace(rb, eps_q=0.0)
    with pytest.raises(InputError, match="eps_q must be positive"):
        PlanningBounds(eps_q=0.0)
    with pytest.raises(InputError, match="t_s must be positive"):
        PlanningBounds(t_s=-1e-3)
    b = PlanningBounds(a_max=90.0).resolve(DEXTAR)
    assert b.a_max_given == (90.0, 90.0) and b.eps_q == DEXTAR.eps_q and b.assumptions.a_max.tolist() == [90.0, 90.0]
    assert resolved(b, DEXTAR) is b  # resolved once: never bound again


def test_execution_class_gives_the_tracker_its_assumptions_with_the_drift_rate_rounded_up():
    """The class's drift per sample ``d`` becomes a rate with ``rate * t_s >= d`` exactly (the tracker's
    difference bound ``2 eps_fast + rate j t_s`` must cover ``j d``); round-to-nearest alone falls short on
    some of these seeded pairs, so the test fails without the upward rounding."""
    from fractions import Fraction

    from crosscert.planner.execution import ExecutionClass, ExecutionKind

    rng = np.random.default_rng(7)
    pairs = [(float(d), float(t)) for d, t in zip(10.0 ** rng.uniform(-9, -5, 400), 10.0 ** rng.uniform(-4, -2, 400))]
    short = [(d, t) for d, t in pairs if Fraction(d / t) * Fraction(t) < Fraction(d)]
    assert short, "no pair where round-to-nearest falls short: the test would not see a missing rounding"
    box = (DEXTAR.xi_lo_array, DEXTAR.xi_hi_array)
    for d, t in short[:20] + pairs[:20]:
        cls = ExecutionClass(ExecutionKind.CARTESIAN, 2e-4, 1e-4, *box, fast_error=1e-4, drift_per_sample=d)
        a = cls.assumptions(Assumptions.for_robot(DEXTAR, t_s=t))
        assert all(Fraction(float(r)) * Fraction(t) >= Fraction(d) for r in a.drift_rate), (d, t)
        assert a.eps_q.tolist() == [2e-4, 2e-4] and a.eps_q_fast.tolist() == [1e-4, 1e-4]
        assert a.xi_lo.tolist() == box[0].tolist() and a.t_s == t


def test_every_field_reads_back_under_its_own_name():
    """Distinct values per field: a holder that permuted its keyword fields (they reach __post_init__ in
    declaration order) would read one back under another's name."""
    s = TrackerSettings(t_s=1e-3, eps_q=1e-4, a_max=(80.0, 81.0), v_max=(2.0, 3.0), xd0=(0.2, 0.3),
                        eps_q_fast=(5e-5, 6e-5), drift_rate=(0.5, 0.6))
    assert (s.t_s, s.eps_q.tolist(), s.a_max.tolist(), s.v_max.tolist(), s.xd0.tolist(), s.eps_q_fast.tolist(),
            s.drift_rate.tolist()) == (1e-3, [1e-4, 1e-4], [80.0, 81.0], [2.0, 3.0], [0.2, 0.3], [5e-5, 6e-5],
                                       [0.5, 0.6])
    rb = RecordingBounds(q_meas=np.zeros((3, 2)), m0=1, t_s=2e-3, eps_q=(1e-4, 2e-4), a_max=(70.0, 71.0),
                         xi_lo=(0.0,), xi_hi=(1.0,), v0_max=(0.1, 0.2), v_max=(4.0, 5.0))
    assert (rb.t_s, rb.eps_q.tolist(), rb.a_max.tolist(), rb.xi_lo.tolist(), rb.xi_hi.tolist(), rb.v0_max.tolist(),
            rb.v_max.tolist()) == (2e-3, [1e-4, 2e-4], [70.0, 71.0], [0.0], [1.0], [0.1, 0.2], [4.0, 5.0])
