"""Adversarial true motions and encoder readings of the DexTAR for containment tests.

The tracker's assumptions are spent to the limit, not sampled gently:

* every pose coordinate accelerates at ``+-A_FRACTION a_max`` at every
  instant (bang-bang, sign chosen at random instants by a feedback on a
  reference, so the motion stays in the workspace); the motion is integrated
  analytically (piecewise-constant acceleration gives an exact
  piecewise-quadratic pose and piecewise-linear velocity), so the truth at
  the samples is exact up to float64 rounding;
* the initial speed sits at the edge of ``xd0``;
* the joints are the closed-form elbows-out IK of the true pose with the
  true geometry, a corner (or the centre) of the calibration box;
* every reading sits at the edge of ``+-eps_q``, with sign patterns that are
  worst for short baselines (alternating), long baselines (blocks) or mixed
  (random).

SI units throughout (m, m/s, m/s^2, rad, s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crosscert.planner.simulate import random_geometry
from crosscert.robots import DEXTAR
from crosscert.robots.dextar import benchmark_crossing
from crosscert.robots.dextar import elbows_out_ik, mode_by_cross_product

#: Fraction of ``a_max`` used at every instant (the rest absorbs rounding).
A_FRACTION = 0.999
#: Fraction of ``eps_q`` of each reading error (float rounding of
#: ``q_true + e`` must not push the error past ``eps_q``).
EDGE = 1.0 - 1e-9
#: Fraction of ``xd0`` of the initial speed, per axis.
V0_FRACTION = 0.999
#: Ranges of the time between bang-bang decisions, s: long (the same sign
#: often lasts longer than the tracker's longest baseline, 16 ms) and short
#: (the velocity stays close to its reference).
LONG_DWELL = (1e-3, 17e-3)
SHORT_DWELL = (1e-3, 6e-3)
#: Reading sign patterns.
PATTERNS = ("alternate", "block", "random")


@dataclass(frozen=True)
class Scenario:
    """One adversarial run: ground truth and readings at ``t_k = k t_s``.

    Attributes
    ----------
    name : str
    seed : int
        Seed of the generator that drew it.
    xi : ndarray (m,)
        True geometry.
    t : ndarray (K,)
        Sample times, s.
    x, xd : ndarray (K, n)
        True pose (m) and velocity (m/s).
    q_true, q_meas : ndarray (K, n)
        True joints and readings, rad.
    mode : ndarray (K,)
        True assembly mode (sign of ``cross(B2 - B1, E - B1)``).
    pattern : tuple of str
        Reading sign pattern of each joint.
    """

    name: str
    seed: int
    xi: np.ndarray
    t: np.ndarray
    x: np.ndarray
    xd: np.ndarray
    q_true: np.ndarray
    q_meas: np.ndarray
    mode: np.ndarray
    pattern: tuple


def bang_bang(rng, t_end, x0, v0, accel, ref, gain, dwell):
    """Knots of a one-coordinate motion whose acceleration is always ``+-accel``.

    At each decision instant ``t_j`` the sign is ``sign(v_des - v)`` with
    ``v_des = v_ref(t_j) - gain (x - x_ref(t_j))``; the next decision comes
    ``dwell`` later, drawn uniformly (so switches fall between samples and
    the same sign often lasts several decisions).

    Parameters
    ----------
    rng : numpy.random.Generator
    t_end : float
        Last time to cover, s.
    x0, v0 : float
        Initial position (m) and velocity (m/s).
    accel : float
        Acceleration magnitude, m/s^2.
    ref : knots
        Reference motion (see :func:`reference`).
    gain : float
        Position feedback gain, 1/s.
    dwell : (float, float)
        Range of the time between decisions, s.

    Returns
    -------
    knots : (t, x, v, a) ndarrays
        Knot times (s), position (m) and velocity (m/s) at the knots, and the
        acceleration (m/s^2) on ``[t_j, t_{j+1})``.
    """
    t, x, v, a = [0.0], [float(x0)], [float(v0)], []
    while t[-1] <= t_end:
        x_ref, v_ref = sample_knots(ref, t[-1])
        v_des = v_ref - gain * (x[-1] - x_ref)
        aj = accel if v_des >= v[-1] else -accel
        T = float(rng.uniform(*dwell))
        a.append(aj)
        x.append(x[-1] + T * (v[-1] + 0.5 * aj * T))
        v.append(v[-1] + aj * T)
        t.append(t[-1] + T)
    return np.array(t), np.array(x), np.array(v), np.array(a)


def reference(x0, phases):
    """Knots of a reference that starts at rest at ``x0`` (m) and follows ``phases``.

    ``phases`` is a sequence of ``(duration (s), acceleration (m/s^2))``; the
    last velocity is held afterwards.
    """
    t, x, v, a = [0.0], [float(x0)], [0.0], []
    for T, aj in phases:
        a.append(float(aj))
        x.append(x[-1] + T * (v[-1] + 0.5 * aj * T))
        v.append(v[-1] + aj * T)
        t.append(t[-1] + T)
    a.append(0.0)
    return np.array(t), np.array(x), np.array(v), np.array(a)


def sample_knots(knots, t):
    """Exact position and velocity at times ``t`` (s) of piecewise-constant-acceleration knots.

    Before the first knot nothing is defined; after the last one the motion
    keeps the last acceleration.
    """
    kt, kx, kv, ka = knots
    j = np.searchsorted(kt, t, side="right") - 1
    tau = t - kt[j]
    a = ka[np.minimum(j, len(ka) - 1)]
    return kx[j] + tau * (kv[j] + 0.5 * a * tau), kv[j] + a * tau


def reading_signs(rng, K, pattern):
    """Signs ``+-1`` of the reading errors of one joint over ``K`` samples.

    ``alternate`` flips every sample (every odd-span difference errs by
    ``2 eps_q``); ``block`` keeps a sign for a block of ``L`` in {1, 2, 4, 8, 16}
    samples (differences over ``L`` samples err by ``2 eps_q``); ``random``
    draws each sign.
    """
    if pattern == "alternate":
        return np.where(np.arange(K) % 2 == 0, 1.0, -1.0) * rng.choice([-1.0, 1.0])
    if pattern == "block":
        L = int(rng.choice([1, 2, 4, 8, 16]))
        phase = int(rng.integers(0, 2 * L))
        return np.where(((np.arange(K) + phase) // L) % 2 == 0, 1.0, -1.0)
    if pattern == "random":
        return rng.choice([-1.0, 1.0], size=K)
    raise ValueError(pattern)


def readings(rng, q_true, eps_q, patterns):
    """Readings ``q_true + s_k eps_q EDGE``, checked to err by at most ``eps_q``.

    The float difference ``q_meas - q_true`` errs from the exact one by less
    than ``1e-15`` rad, far below the margin ``eps_q (1 - EDGE)`` (~1e-13
    rad), so checking it against ``eps_q (1 - (1 - EDGE) / 2)`` proves the
    exact error is within ``eps_q``.
    """
    K, n = q_true.shape
    signs = np.stack([reading_signs(rng, K, p) for p in patterns], axis=1)
    q = q_true + signs * (eps_q * EDGE)
    err = np.abs(q - q_true)
    assert np.all(err <= eps_q * (1.0 - (1.0 - EDGE) / 2)), "a reading left +-eps_q"
    assert np.all(err >= 0.99 * eps_q), "a reading is not at the edge"
    return q


def scenario(name, seed, *, xi, t_end, x0, refs, gain=30.0, t_s=DEXTAR.t_s, times=None):
    """Draw one scenario (see :class:`Scenario`).

    Parameters
    ----------
    name : str
    seed : int
        Seed of everything random in it (switch instants, initial velocity
        signs, reading patterns).
    xi : ndarray (m,)
        True geometry.
    t_end : float
        Duration, s.
    x0 : array (n,)
        Initial pose, m.
    refs : sequence of (knots, dwell), one per coordinate
        Reference motion (:func:`reference`) and the range of the time between
        bang-bang decisions (s), see :func:`bang_bang`.
    gain : float
        Position feedback gain, 1/s.
    times : array (K,), optional
        The true sample times, s (an uneven recording: jitter, dropped
        samples); ``k t_s`` up to ``t_end`` by default.

    The initial velocity is ``V0_FRACTION xd0`` with a random sign per axis.
    """
    rng = np.random.default_rng(seed)
    n = DEXTAR.n
    accel = A_FRACTION * np.asarray(DEXTAR.a_max, dtype=float)
    v0 = V0_FRACTION * np.asarray(DEXTAR.xd0, dtype=float) * rng.choice([-1.0, 1.0], size=n)
    t = np.arange(int(round(t_end / t_s)) + 1) * t_s if times is None else np.asarray(times, dtype=float)
    K = len(t)
    x = np.empty((K, n))
    xd = np.empty((K, n))
    for i, (ref, dwell) in enumerate(refs):
        knots = bang_bang(rng, t[-1], x0[i], v0[i], accel[i], ref, gain, dwell)
        x[:, i], xd[:, i] = sample_knots(knots, t)
    q_true = elbows_out_ik(x, xi)
    if not np.all(np.isfinite(q_true)):
        raise ValueError(f"{name}: the motion leaves the workspace")
    patterns = tuple(str(p) for p in rng.choice(PATTERNS, size=n))
    q_meas = readings(rng, q_true, DEXTAR.eps_q, patterns)
    mode = mode_by_cross_product(x, q_true, xi)
    return Scenario(name, seed, np.asarray(xi, dtype=float), t, x, xd, q_true, q_meas, mode, patterns)


def geometries(rng, count):
    """The centre of ``[xi]`` then ``count - 1`` random corners."""
    out = [DEXTAR.xi_center]
    while len(out) < count:
        out.append(random_geometry(DEXTAR, rng, corners=True))
    return out


#: Centres of the far-from-the-locus motions, m (mode +1 above the locus, -1 below).
FAR_CENTRES = ((0.0, 0.125), (-0.03, 0.115), (0.0, 0.035), (0.02, 0.035))


def far_scenarios(count, seed, t_end=0.2):
    """Bang-bang wandering around fixed points far from the Type 2 locus.

    Each coordinate accelerates at ``+-A_FRACTION a_max`` and is steered back
    to the centre with long dwells (up to 17 ms, longer than the tracker's
    longest baseline), reaching ~1.3 m/s and ~15 mm from the centre.
    """
    rng = np.random.default_rng(seed)
    out = []
    for i, xi in enumerate(geometries(rng, count)):
        c = FAR_CENTRES[i % len(FAR_CENTRES)]
        refs = [(reference(ci, ()), LONG_DWELL) for ci in c]
        out.append(scenario(f"far{i}", seed * 1000 + i, xi=xi, t_end=t_end, x0=c, refs=refs))
    return out


def near_scenarios(count, seed, t_end=0.16, a_ref=55.0, v_cross=(1.3, 1.6), v_bounce=(1.0, 1.5), times=None):
    """Bang-bang runs through (even ``i``) or up to and back from (odd ``i``) the Type 2 locus.

    The ``Y`` coordinate follows a reference down the ``Y`` axis through the
    nominal singular point of the benchmark (``benchmark_crossing().point``):

    * crossing: ramp to ``-v`` (``v_cross``, 1.3-1.6 m/s) at ``a_ref``, cruise
      from 15 mm before to 15 mm past the singular point, ramp back to rest;
    * bounce: ramp to ``-v`` (``v_bounce``, 1.0-1.5 m/s), cruise 4 mm, ramp down to rest
      at ``y_s + delta`` (``delta`` in [-2, 6] mm: it may just pass the locus)
      and retrace the same way up.

    The ``Y`` dwells are short (1-6 ms) so the speed stays within ~0.3 m/s of
    the reference; ``X`` wanders around a small offset with long dwells.
    Every coordinate accelerates at ``+-A_FRACTION a_max`` at every instant.
    ``times``: the true sample times, as for :func:`scenario`.
    """
    rng = np.random.default_rng(seed)
    y_s = float(benchmark_crossing().point[1])
    out = []
    for i, xi in enumerate(geometries(rng, count)):
        x_off = float(rng.uniform(-0.004, 0.004))
        if i % 2 == 0:
            v = float(rng.uniform(*v_cross))
            T = v / a_ref
            cruise = 0.030 / v
            y0 = y_s + 0.5 * a_ref * T**2 + 0.015
            phases = ((T, -a_ref), (cruise, 0.0), (T, a_ref))
            name = f"cross{i}"
        else:
            v = float(rng.uniform(*v_bounce))
            T = v / a_ref
            cruise = 0.004 / v
            y0 = y_s + float(rng.uniform(-0.002, 0.006)) + a_ref * T**2 + 0.004
            phases = ((T, -a_ref), (cruise, 0.0), (T, a_ref), (T, a_ref), (cruise, 0.0), (T, -a_ref))
            name = f"bounce{i}"
        refs = [(reference(x_off, ()), LONG_DWELL), (reference(y0, phases), SHORT_DWELL)]
        out.append(scenario(name, seed * 1000 + 500 + i, xi=xi, t_end=t_end, x0=(x_off, y0), refs=refs, times=times))
    return out
