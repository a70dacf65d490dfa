"""The planner's per-process models (planner.models): one bounded cache, by robot value and thread."""

from __future__ import annotations

import threading
from dataclasses import replace

from crosscert.planner import models
from crosscert.robots import DEXTAR


def _in_thread(fn):
    out = []
    t = threading.Thread(target=lambda: out.append(fn()))
    t.start()
    t.join()
    return out[0]


def test_a_thread_gets_the_same_models_again():
    assert models.kinematic_model(DEXTAR) is models.kinematic_model(DEXTAR)
    assert models.interval_model(DEXTAR) is models.interval_model(DEXTAR)
    # equal values are the same key: a robot rebuilt with the same parameters reuses them
    assert models.kinematic_model(replace(DEXTAR)) is models.kinematic_model(DEXTAR)


def test_another_thread_gets_models_of_its_own():
    # CasADi functions must not be called from two threads at once
    mine = models.kinematic_model(DEXTAR)
    theirs = _in_thread(lambda: models.kinematic_model(DEXTAR))
    assert theirs is not mine
    assert theirs.robot == mine.robot


def test_variants_of_a_robot_are_kept_apart_and_the_cache_is_bounded():
    variants = [replace(DEXTAR, eps_q=(1.0 + 0.01 * i) * DEXTAR.eps_q) for i in range(models.MODELS_KEPT + 1)]
    first = models.kinematic_model(variants[0])
    assert first.robot == variants[0]
    built = [models.kinematic_model(v) for v in variants[1:]]
    assert all(k.robot == v for k, v in zip(built, variants[1:]))
    assert len(models._KINEMATIC) <= models.MODELS_KEPT
    # the least recently used variant was dropped: it is built again
    assert models.kinematic_model(variants[0]) is not first
