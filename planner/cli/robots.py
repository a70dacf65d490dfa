"""``crosscert robots``: every robot (built-in, from an installed entry point, from a file), and the validation of one."""

from __future__ import annotations

import sys

import numpy as np

from crosscert.robots.registry import get_entry, listed_robots
from crosscert.verifier.validation import validate

__all__ = ["robots"]


def _row(entry, origin) -> str:
    r = entry.robot
    fmt = lambda v: "(" + ", ".join(f"{x:g}" for x in np.atleast_1d(v)) + ")"  # noqa: E731
    extras = [name for name, has in (("dynamics", entry.dynamics is not None),
                                      ("benchmark crossing", entry.benchmark is not None),
                                      ("reference motion", entry.motion is not None)) if has]
    a = r.assumptions  # the units of each bound come from it
    return (f"{entry.name}: n = {r.n}, m = {r.m}, t_s = {r.t_s:g} s, eps_q = {r.eps_q:g} {a.unit('eps_q')}, "
            f"a_max = {fmt(r.a_max)} {a.unit('a_max')}, xd0 = {fmt(r.xd0)} {a.unit('xd0')}; "
            f"ships {', '.join(extras) if extras else 'no task'}; from {origin}")


def robots(a) -> int:
    """``crosscert robots``: list the robots (and those of ``--robot FILE.py:NAME``) with where each comes from, or
    validate one (``--validate NAME``); exit code 0 or 2 (a robot that does not load: one line)."""
    if a.validate is None:
        for _key, entry, origin in listed_robots(a.files):
            print(_row(entry, origin))
        return 0
    entry = get_entry(a.validate)
    report = validate(entry.robot, seed=a.seed)
    for c in report.checks:
        print(f"{c.name:>22}: {c.outcome.value:<7} {c.message}")
    if report.ok:
        print(f"{entry.name}: every check passed")
        return 0
    names = ", ".join(c.name for c in report.failures)
    print(f"crosscert: error: robot {entry.name} fails validation ({names}); see the report above", file=sys.stderr)
    return 2
