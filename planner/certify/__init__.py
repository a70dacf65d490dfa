"""Certification at planning time: a plan, a speed, and a crossing task.

* :mod:`planner.certify.plan` — :func:`~planner.certify.plan.certify_plan`
  (the tracker on inputs covering every admissible execution of one plan),
  ``certify_speed`` and the speed searches (``search_v_min``,
  ``minimal_v_sing``);
* :mod:`planner.certify.crossing` — :func:`~planner.certify.crossing.certify_crossing`:
  the whole certification of a task (plans, speed search, Monte Carlo
  confirmation, refutation), returning a ``CrossingCertificate``.

Import from the defining module (this package re-exports nothing, so that
importing one of them does not import the other).
"""
