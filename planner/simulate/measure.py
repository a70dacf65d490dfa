"""What the encoders read and which geometry is true: the one quantiser and the geometry draw."""

from __future__ import annotations

from enum import StrEnum

import numpy as np

from crosscert.robots.assumptions import check_bound
from crosscert.robots.base import Robot
from crosscert.robots.errors import InputError

__all__ = ["Quantisation", "quantise", "random_geometry"]

#: Shrink of a uniform reading error, relative: rounding of ``q_true + e``
#: cannot then push ``|e|`` past ``eps_q``.
UNIFORM_SHRINK = 1e-9


class Quantisation(StrEnum):
    """How a simulated encoder turns a true joint value into a reading (error within ``eps_q``)."""

    FLOOR = "floor"  #: ``eps_q * floor(q / eps_q)``: an incremental encoder's count
    ROUND = "round"  #: ``eps_q * round(q / eps_q)``: error within ``eps_q / 2``
    UNIFORM = "uniform"  #: ``q + e``, ``e`` uniform in ``(-eps_q, eps_q)``


def quantise(q_true, eps_q: float, kind: Quantisation | str, rng=None) -> np.ndarray:
    """Encoder readings of the joints ``q_true`` (rad) with error bound ``eps_q`` (rad).

    Parameters
    ----------
    q_true : array_like, shape (K, n)
        True joints, rad.
    eps_q : float
        Error bound, rad: ``|reading - q_true| <= eps_q`` holds for every kind
        (the result is clipped to it, against rounding of the grid products).
    kind : Quantisation or str
    rng : numpy.random.Generator or int, optional
        For ``uniform``.

    Returns
    -------
    ndarray, shape (K, n)
    """
    q_true = np.asarray(q_true, dtype=float)
    eps_q = check_bound("eps_q", eps_q)
    try:
        kind = Quantisation(kind)
    except ValueError:
        raise InputError(f"quantisation must be one of {[k.value for k in Quantisation]}, got {kind!r}") from None
    if kind is Quantisation.FLOOR:
        q = eps_q * np.floor(q_true / eps_q)
    elif kind is Quantisation.ROUND:
        q = eps_q * np.round(q_true / eps_q)
    else:
        q = q_true + eps_q * (1.0 - UNIFORM_SHRINK) * np.random.default_rng(rng).uniform(-1.0, 1.0, q_true.shape)
    return np.clip(q, q_true - eps_q, q_true + eps_q)


def random_geometry(robot: Robot, rng=None, *, corners: bool = False) -> np.ndarray:
    """A random true geometry in the calibration box.

    Parameters
    ----------
    robot : Robot
    rng : numpy.random.Generator or int or None
        Generator, or a seed for ``numpy.random.default_rng``.
    corners : bool
        Draw a random corner of ``[xi_lo, xi_hi]`` instead of a uniform point.

    Returns
    -------
    ndarray, shape (m,)
        Parameters, SI.
    """
    rng = np.random.default_rng(rng)
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    if corners:
        return np.where(rng.integers(0, 2, size=robot.m) == 1, hi, lo)
    return np.clip(lo + (hi - lo) * rng.random(robot.m), lo, hi)
