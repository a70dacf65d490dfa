"""crosscert: certified assembly-mode tracking of parallel robots through Type 2 singularities.

The three layers install as sub-packages of this one (``crosscert.robots`` at
the bottom, then ``crosscert.verifier``, then ``crosscert.planner`` with the
``crosscert`` command); see docs/architecture.md.  This module gives the calls
most users start from, imported on first use so that ``import crosscert.robots``
stays light::

    import crosscert
    cert = crosscert.certify_crossing(crosscert.benchmark_task())    # plan and certify (the main job)
    result = crosscert.track_window(traj, settings)                   # check a recording
"""

from __future__ import annotations

import importlib
from pathlib import Path as _Path

# In a source checkout the three layers are this folder's siblings (pyproject.toml's package-dir
# installs them inside it).  Python run from the checkout finds this folder first, before the
# installed package: let `crosscert.verifier` and the others resolve to the siblings then.
_HERE = _Path(__file__).resolve().parent
if not (_HERE / "verifier").is_dir() and all((_HERE.parent / p / "__init__.py").is_file()
                                              for p in ("robots", "verifier", "planner")):
    __path__.append(str(_HERE.parent))

#: name -> defining module (relative to this package), read on first access.
_API = {
    # planning: the main job
    "certify_crossing": "planner.certify.crossing",
    "CrossingCertificate": "planner.certify.certificate",
    "benchmark_task": "planner.task",
    "CrossingTask": "planner.task",
    "PlanningBounds": "planner.task",
    "plan_crossing": "planner.plan",
    # checking a recording
    "Tracker": "verifier.tracker",
    "TrackerSettings": "verifier.settings",
    "Verdict": "verifier.settings",
    "track": "verifier.tracker",
    "track_window": "verifier.window.offline",
    "OnlineMonitor": "verifier.window.online",
    "Trajectory": "verifier.trajectory",
    "read_trajectory": "verifier.trajfile",
    "open_recording": "verifier.recordings",
    # robots and errors
    "validate": "verifier.validation",
    "get_robot": "robots.registry",
    "get_entry": "robots.registry",
    "available_robots": "robots.registry",
    "CrosscertError": "robots.errors",
    "InputError": "robots.errors",
}

__all__ = sorted(_API)


def __getattr__(name: str):
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'crosscert' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
