"""Limits of a time scaling and their rows ``A a + B b <= C`` on the grid.

By the chain rule every bound is linear in ``(a, b) = (sddot, sdot^2)``:
``q'^2 b <= qd_max^2``, ``|q' a + q'' b| <= qdd_max``, ``|x' a + x'' b| <= a_max``.
:func:`path_rows` writes them node by node, :func:`interval_matrix` on both
ends of every interval with ``a_i = (b_{i+1} - b_i) / (2 ds)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from crosscert.robots.errors import InputError

from .path import PathSamples

__all__ = ["LinearPathConstraint", "ScalingLimits"]


@dataclass(frozen=True, eq=False)
class LinearPathConstraint:
    """Extra node-wise bound ``A_i a + B_i b_i <= C_i`` (e.g. torques of a dynamic model).

    Imposed at every node ``i`` for both one-sided path accelerations (of the
    intervals on either side), like the built-in acceleration bounds.

    Attributes
    ----------
    A : ndarray, shape (N + 1, k)
        Coefficients of the path acceleration ``a`` (units of C per m/s^2).
    B : ndarray, shape (N + 1, k)
        Coefficients of ``b = sdot^2`` (units of C per m^2/s^2).
    C : ndarray, shape (N + 1, k)
        Bounds (any unit, e.g. N m).
    name : str
        Shown in error messages.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    name: str = "extra"

    def __post_init__(self) -> None:
        arrs = []
        for nm in ("A", "B", "C"):
            try:
                v = np.array(getattr(self, nm), dtype=float)
            except (TypeError, ValueError) as exc:
                raise InputError(f"LinearPathConstraint {self.name}: {nm} must be numeric") from exc
            if v.ndim == 1:
                v = v[:, None]
            if v.ndim != 2 or not np.all(np.isfinite(v)):
                raise InputError(f"LinearPathConstraint {self.name}: {nm} must be a finite (N+1, k) array")
            v.setflags(write=False)
            object.__setattr__(self, nm, v)
            arrs.append(v)
        if not arrs[0].shape == arrs[1].shape == arrs[2].shape:
            raise InputError(f"LinearPathConstraint {self.name}: A, B, C shapes differ: "
                             f"{[a.shape for a in arrs]}")


@dataclass(frozen=True, eq=False)
class ScalingLimits:
    """Kinematic limits of a time scaling; ``None`` leaves a quantity unbounded.

    Attributes
    ----------
    qd_max : float or array_like, shape (n,), optional
        Componentwise joint speed bound ``|qdot| <= qd_max``, rad/s.
    qdd_max : float or array_like, shape (n,), optional
        Componentwise joint acceleration bound, rad/s^2.
    a_max : float or array_like, shape (n,), optional
        Componentwise end-effector acceleration bound ``|xddot| <= a_max``,
        m/s^2 (the tracker's ``[a_max]``).
    extra : tuple of LinearPathConstraint
        Further linear bounds on the same grid (e.g. actuator torques).

    Notes
    -----
    An infinite entry leaves that component unbounded, so these are not
    checked by :func:`robots.arguments.vector` (which requires finite entries).
    """

    qd_max: object = None
    qdd_max: object = None
    a_max: object = None
    extra: tuple = ()

    def __post_init__(self) -> None:
        for nm in ("qd_max", "qdd_max", "a_max"):
            v = getattr(self, nm)
            if v is None:
                continue
            try:
                arr = np.array(v, dtype=float).reshape(-1)
            except (TypeError, ValueError) as exc:
                raise InputError(f"{nm} must be a number or a vector of numbers, got {v!r}") from exc
            if arr.size == 0 or not np.all(arr > 0) or np.any(np.isnan(arr)):
                raise InputError(f"{nm} must be positive, got {v!r}")
            arr.setflags(write=False)
            object.__setattr__(self, nm, arr)
        extra = tuple(self.extra)
        if not all(isinstance(e, LinearPathConstraint) for e in extra):
            raise InputError("extra must be a tuple of LinearPathConstraint")
        object.__setattr__(self, "extra", extra)


def per_joint(v: np.ndarray | None, n: int, name: str) -> np.ndarray | None:
    """A :class:`ScalingLimits` bound as ``n`` entries (a scalar broadcast), or None when unbounded."""
    if v is None:
        return None
    if v.size == 1:
        return np.full(n, float(v[0]))
    if v.size != n:
        raise InputError(f"{name} must be a scalar or have {n} entries, got {v.size}")
    return np.asarray(v, dtype=float)


def check_nodes(e: LinearPathConstraint, n_nodes: int) -> None:
    """InputError unless ``e`` is given on ``n_nodes`` nodes (the path's ``N + 1``)."""
    if e.A.shape[0] != n_nodes:
        raise InputError(f"LinearPathConstraint {e.name} has {e.A.shape[0]} nodes, the path {n_nodes}")


@dataclass(frozen=True, eq=False)
class PathRows:
    """All bounds on the grid: ``b <= ub`` and normalised rows ``A a + B b <= C``.

    Attributes
    ----------
    ub : ndarray, shape (N + 1,)
        Upper bound of ``b`` from the joint speeds, m^2/s^2, inf where unbounded.
    A, B, C : ndarray, shape (N + 1, k)
        Rows divided by their bound, so each is O(1) for the solver.
    """

    ub: np.ndarray
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray


def path_rows(samples: PathSamples, limits: ScalingLimits) -> PathRows:
    """Every bound of ``limits`` at the nodes of ``samples``.

    Parameters
    ----------
    samples : PathSamples
    limits : ScalingLimits

    Returns
    -------
    PathRows

    Raises
    ------
    InputError
        A bound with the wrong number of entries, or an extra constraint on another grid.
    """
    n, N1 = samples.q.shape[1], samples.s.shape[0]
    qd = per_joint(limits.qd_max, n, "qd_max")
    qdd = per_joint(limits.qdd_max, n, "qdd_max")
    am = per_joint(limits.a_max, n, "a_max")
    ub = np.full(N1, np.inf)
    if qd is not None:
        with np.errstate(divide="ignore"):
            ub = np.min((qd / np.abs(samples.q_s)) ** 2, axis=1)  # q'=0 gives inf
    As, Bs, Cs = [], [], []
    # Rows are divided by their bound so all are O(1) for the solver.
    for lim, d1, d2 in ((qdd, samples.q_s, samples.q_ss), (am, samples.x_s, samples.x_ss)):
        if lim is None:
            continue
        keep = np.any(d1 != 0, axis=0) | np.any(d2 != 0, axis=0)  # drop 0 <= lim rows
        for sgn in (1.0, -1.0):
            As.append(sgn * d1[:, keep] / lim[keep])
            Bs.append(sgn * d2[:, keep] / lim[keep])
            Cs.append(np.ones((N1, int(keep.sum()))))
    for e in limits.extra:
        check_nodes(e, N1)
        scale = np.maximum(np.maximum(np.abs(e.A), np.abs(e.B)), np.abs(e.C))
        scale[scale == 0.0] = 1.0
        As.append(e.A / scale)
        Bs.append(e.B / scale)
        Cs.append(e.C / scale)
    if As:
        A, B, C = np.hstack(As), np.hstack(Bs), np.hstack(Cs)
    else:
        A = B = C = np.zeros((N1, 0))
    return PathRows(ub=ub, A=A, B=B, C=C)


def interval_matrix(rows: PathRows, ds: float) -> tuple[sp.csr_matrix, np.ndarray]:
    """``G b <= h`` for both ends of every interval, with ``a_i = (b_{i+1} - b_i) / (2 ds)``.

    Parameters
    ----------
    rows : PathRows
        The node rows, ``k`` per node.
    ds : float
        Grid step, m.

    Returns
    -------
    G : scipy.sparse.csr_matrix, shape (2 k N, N + 1)
    h : ndarray, shape (2 k N,)
    """
    N1, k = rows.A.shape
    N = N1 - 1
    i = np.arange(N)
    rows_i = np.concatenate([i, i])
    cols = np.concatenate([i, i + 1])  # b_i, b_{i+1}
    blocks, rhs = [], []
    for j in range(k):
        for m, right in ((i, False), (i + 1, True)):  # node of the bound: left or right end
            # A_m (b_{i+1} - b_i) / (2 ds) + B_m b_m <= C_m
            Am, Bm = rows.A[m, j] / (2.0 * ds), rows.B[m, j]
            coef_i = -Am + (0.0 if right else Bm)
            coef_i1 = Am + (Bm if right else 0.0)
            blocks.append(sp.csr_matrix((np.concatenate([coef_i, coef_i1]), (rows_i, cols)),
                                        shape=(N, N1)))
            rhs.append(rows.C[m, j])
    if not blocks:
        return sp.csr_matrix((0, N1)), np.zeros(0)
    return sp.vstack(blocks).tocsr(), np.concatenate(rhs)
