"""Start guesses of the counterexample NLPs (:mod:`planner.refute.nlp`): a motion through the readings.

:func:`fk_branch_guess` follows one assembly mode's forward-kinematics branch along the readings (batched
Newton in chunks, one sample at a time where a chunk fails, refusing a jump to another assembly of the same
mode); :func:`fk_crossing_guess` joins the two modes' branches at the sample nearest the locus.  A guess only
starts IPOPT: whatever it returns, a counterexample counts only once the trusted check verifies it.  SI units.
"""

from __future__ import annotations

import numpy as np

from crosscert.robots.errors import SimulationError
from crosscert.robots.kinematics import KinematicModel

__all__ = ["fk_branch_guess", "fk_crossing_guess", "GAP_TIE"]


#: Largest chunk of samples solved in one batched Newton by :func:`fk_branch_guess`.
_MAX_CHUNK = 64
#: Smallest move between consecutive samples a chunk always accepts, as a fraction of the smallest
#: side of the robot's workspace box (the continuity check is relative to the last step otherwise).
_CONTINUITY_FLOOR = 1e-3
#: Largest jump (fraction of the smallest side of the workspace box) from the last pose to a fresh
#: forward-kinematics solution that :func:`fk_branch_guess` takes as the same branch reappearing.
_JUMP_FRACTION = 0.05


def fk_branch_guess(kin: KinematicModel, q_meas, xi, m0: int) -> tuple[np.ndarray, np.ndarray]:
    """The forward kinematics of every sample in assembly mode ``m0``, by continuation.

    For a crossing this is the recording's own path before the locus and its
    reflection (the other FK solution) after it: the "bounce" the NLP starts
    from.  Samples with no mode-``m0`` solution (near the locus, where the two
    solutions merge and vanish for this ``xi``) are linearly interpolated.

    Parameters
    ----------
    kin : KinematicModel
        The robot's kinematics.
    q_meas : array_like, shape (K, n)
        Joints, rad.
    xi : array_like, shape (m,)
        Geometry, SI.
    m0 : int
        Assembly mode, +1 or -1.

    Returns
    -------
    X : ndarray, shape (K, n)
        Poses, m.
    solved : ndarray of bool, shape (K,)
        Samples where an FK solution of mode ``m0`` was found (others interpolated).

    Raises
    ------
    SimulationError
        If no sample has an FK solution of mode ``m0``.
    """
    Q = np.asarray(q_meas, dtype=float)
    K = Q.shape[0]
    X = np.full((K, kin.n), np.nan)
    solved = np.zeros(K, dtype=bool)
    _continue_branch(kin, Q, xi, m0, X, solved)
    if not solved.any():
        raise SimulationError(f"{kin.robot.name}: no sample has a forward-kinematics solution in mode {m0:+d}")
    idx = np.nonzero(solved)[0]
    for j in range(kin.n):
        X[:, j] = np.interp(np.arange(K), idx, X[idx, j])
    return X, solved


def _continue_branch(kin: KinematicModel, Q: np.ndarray, xi, m0: int, X: np.ndarray, solved: np.ndarray) -> None:
    """Fill ``X`` (m) and ``solved`` in place with the mode-``m0`` FK of the joints ``Q`` (rad), by continuation.

    Continuation in chunks: one batched Newton per chunk, each row started
    from the last pose extrapolated at the last step.  A chunk keeps its
    longest prefix whose rows converged, stayed in mode ``m0`` and moved
    continuously; the first row after it is solved alone, as the one-sample
    continuation would (so chunks only skip work, they never jump branch).
    """
    K = Q.shape[0]
    side = float(np.min(kin.robot.x_hi_array - kin.robot.x_lo_array))
    prev = step = None
    k, chunk, refused = 0, 1, 0  # refused: samples since a jump to another assembly was refused (0: none)
    while k < K:
        if prev is not None and chunk > 1:
            Xc, whole = _chunk_prefix(kin, Q, xi, m0, k, chunk, prev, step, side)
            n_ok = Xc.shape[0]
            if n_ok:
                X[k:k + n_ok], solved[k:k + n_ok] = Xc, True
                last = Xc[n_ok - 1]
                step = last - (Xc[n_ok - 2] if n_ok >= 2 else prev)
                prev = last
                k += n_ok
            if whole:
                chunk = min(2 * chunk, _MAX_CHUNK)
                continue
            chunk = 1
            if k >= K:
                break
        x, refused = _next_pose(kin, Q, xi, m0, k, prev, refused, side)
        if x is not None:
            step = np.zeros(kin.n) if prev is None or not solved[k - 1] else x - prev
            X[k], solved[k], prev = x, True, x
            chunk = 2
        k += 1


def _chunk_prefix(kin: KinematicModel, Q: np.ndarray, xi, m0: int, k: int, chunk: int, prev: np.ndarray,
                  step: np.ndarray, side: float) -> tuple[np.ndarray, bool]:
    """One batched Newton over up to ``chunk`` samples from ``k``, started along the last step.

    Returns
    -------
    Xc : ndarray, shape (n_ok, n)
        Poses (m) of the longest prefix of the chunk whose rows converged,
        are in mode ``m0`` and moved continuously from ``prev`` (m) (at most
        four times the last step ``step`` (m), or ``_CONTINUITY_FLOOR`` of the
        smallest side ``side`` (m) of the workspace box).
    whole : bool
        Every row of the chunk was kept.
    """
    ks = np.arange(k, min(Q.shape[0], k + chunk))
    guess = prev[None, :] + (ks - k + 1)[:, None] * step[None, :]
    Xc, ok = kin.fk_batch(Q[ks], xi, guess)
    good = ok.copy()
    if good.any():
        good[good] = kin.mode_batch(Xc[good], Q[ks[good]], xi) == m0
    moves = np.max(np.abs(np.diff(np.vstack([prev[None, :], Xc]), axis=0)), axis=1)
    good &= moves <= np.maximum(4.0 * np.max(np.abs(step)), _CONTINUITY_FLOOR * side)
    n_ok = int(np.argmin(good)) if not good.all() else good.size
    return Xc[:n_ok], n_ok == ks.size


def _next_pose(kin: KinematicModel, Q: np.ndarray, xi, m0: int, k: int, prev: np.ndarray | None, refused: int,
               side: float) -> tuple[np.ndarray | None, int]:
    """The mode-``m0`` pose (m) of sample ``k`` alone, or None; and the updated count ``refused``.

    Newton from the last pose ``prev`` first; failing that (first sample, or
    it fell into the other mode), every FK solution, the nearest to ``prev``
    of mode ``m0`` (unless a refused jump makes this sample skip the search).
    ``refused`` counts the samples since a jump to another assembly was
    refused (0: none); it is 0 again once a pose is found.
    """
    x = None
    if prev is not None:
        Xk, ok = kin.fk_batch(Q[k:k + 1], xi, prev[None, :])
        if ok[0] and kin.mode(Xk[0], Q[k], xi) == m0:
            x = Xk[0]
    # After a refused jump, all the solutions (costly: 0.4 s a sample for three joints) are sought
    # again only 1, 2, 4, ... samples later; the continuation above is tried at every sample.
    if x is None and not refused & (refused - 1):  # no continuation (first sample, or it fell into the other mode)
        sols = kin.fk_all(Q[k], xi)
        mine = [s for s in sols if kin.mode(s, Q[k], xi) == m0]
        if mine:
            # Nearest to the last pose keeps the branch; the first sample takes
            # the lexicographically first solution of its mode.  A nearest one
            # farther than _JUMP_FRACTION of the workspace is another assembly
            # of that mode (the branch vanished for this xi): the sample is
            # interpolated instead, a jump there would start IPOPT thousands of
            # a_max away from feasibility.
            x = mine[0] if prev is None else min(mine, key=lambda s: float(np.max(np.abs(s - prev))))
            if prev is not None and float(np.max(np.abs(x - prev))) > _JUMP_FRACTION * side:
                x, refused = None, max(refused, 1)
    if x is None and refused:
        refused += 1
    if x is not None:
        refused = 0
    return x, refused


#: Relative tolerance (and, times 1 um, absolute in m) within which two branch gaps of
#: :func:`fk_crossing_guess` are equal.
GAP_TIE = 1e-9


def fk_crossing_guess(kin: KinematicModel, q_meas, xi, m0: int) -> tuple[np.ndarray, int]:
    """A crossing through the readings: mode-``m0`` FK up to the sample nearest the locus, mode ``-m0`` after.

    For a bounce recording this is its own path up to the turning point and
    the reflection of the way back (the other FK solution): the crossing the
    NLP starts from.  The switch sample is where the two branches
    (:func:`fk_branch_guess` of each mode) come closest, i.e. where the
    readings come nearest the locus of ``xi``; if that is not on the locus
    the guess jumps there, and IPOPT has to move ``xi`` and the path.

    Parameters
    ----------
    kin : KinematicModel
        The robot's kinematics.
    q_meas : array_like, shape (K, n)
        Joints, rad.
    xi : array_like, shape (m,)
        Geometry, SI.
    m0 : int
        Initial assembly mode, +1 or -1.

    Returns
    -------
    X : ndarray, shape (K, n)
        Poses, m.
    k_switch : int
        Last sample taken from the mode-``m0`` branch.

    Raises
    ------
    SimulationError
        If no sample has an FK solution of mode ``m0``, or none of mode ``-m0``.
    """
    Xa, ok_a = fk_branch_guess(kin, q_meas, xi, m0)
    Xb, ok_b = fk_branch_guess(kin, q_meas, xi, -m0)
    gap = np.max(np.abs(Xa - Xb), axis=1)
    # Samples where neither branch was solved lie beyond the fold, where the
    # readings pass the locus of xi; else the branches come closest at the
    # turn, often over a run of equal readings (the joints stop there):
    # switch in the middle of the first such run.
    # Equal readings give gaps equal up to Newton's last bits, which differ between machines (libm, SIMD
    # paths): a gap within GAP_TIE of the smallest counts as the smallest, so the run, and the switch in its
    # middle, is the same everywhere.
    none = ~(ok_a | ok_b)
    if none.any():
        at = none
    else:
        g = np.where(ok_a & ok_b, gap, np.inf)
        at = g <= np.min(g) * (1.0 + GAP_TIE) + GAP_TIE * 1e-6
    k0 = int(np.argmax(at))
    k1 = k0 + int(np.argmin(at[k0:])) if not at[k0:].all() else at.size
    k_switch = (k0 + k1 - 1) // 2
    X = np.concatenate([Xa[:k_switch + 1], Xb[k_switch + 1:]])
    return X, k_switch
