"""Argument checks: the one place where a function's numbers are checked and coerced (names, shapes, ranges).

Every public function and dataclass of crosscert that takes numbers from a user
checks them here, so a bad value gets the same kind of message everywhere:
the argument's name, what it must be, and what was given.  The error class is
a parameter because a bad robot definition is a :class:`ModelError` while a
bad call is an :class:`InputError`.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import CrosscertError, InputError

__all__ = ["number", "positive", "count", "vector", "direction", "floats", "frozen_array"]


def number(name: str, value, *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False, error: type[CrosscertError] = InputError) -> float:
    """A finite float, optionally within ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``).

    Raises
    ------
    InputError (or ``error``)
        If ``value`` is not a real number, not finite, or out of range.
    """
    if isinstance(value, (bool, np.bool_)):
        raise error(f"{name} must be a number, got {value!r}")
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise error(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(f):
        raise error(f"{name} must be finite, got {value!r}")
    if lo is not None and (f < lo or (lo_open and f == lo)):
        raise error(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {value!r}")
    if hi is not None and f > hi:
        raise error(f"{name} must be <= {hi:g}, got {value!r}")
    return f


def positive(name: str, value, *, allow_zero: bool = False,
             error: type[CrosscertError] = InputError) -> float:
    """A finite float ``> 0`` (``>= 0`` with ``allow_zero``)."""
    return number(name, value, lo=0.0, lo_open=not allow_zero, error=error)


def count(name: str, value, *, error: type[CrosscertError] = InputError) -> int:
    """A non-negative integer (an ``int`` or an integral float; not a bool)."""
    if isinstance(value, (bool, np.bool_)):
        raise error(f"{name} must be a non-negative integer, got {value!r}")
    try:
        i = int(value)
        ok = i == value and i >= 0
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise error(f"{name} must be a non-negative integer, got {value!r}")
    return i


def vector(name: str, value, n: int | None = None, *, broadcast: bool = False, positive: bool = False,
           nonneg: bool = False, error: type[CrosscertError] = InputError) -> np.ndarray:
    """A finite float vector, shape ``(n,)``, as a new read-only array.

    Parameters
    ----------
    name : str
        The argument's name, for messages.
    value : array_like
        The entries; with ``broadcast`` a single number stands for ``n`` equal entries.
    n : int, optional
        The required length (any length when None).
    positive, nonneg : bool
        Require every entry ``> 0`` or ``>= 0``.
    error : type
        The exception class raised (InputError by default).
    """
    try:
        a = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise error(f"{name} must be a vector of numbers, got {value!r}") from None
    if broadcast and n is not None and a.size == 1:
        a = np.full(n, a[0])
    if n is not None and a.shape != (n,):
        many = f"1 or {n}" if broadcast else f"{n}"
        raise error(f"{name} must have {many} entries, got {a.size}")
    if not np.all(np.isfinite(a)):
        raise error(f"{name} must be finite, got {a.tolist()}")
    if positive and not np.all(a > 0):
        raise error(f"{name} must be positive, got {a.tolist()}")
    if nonneg and not np.all(a >= 0):
        raise error(f"{name} must be non-negative, got {a.tolist()}")
    a.setflags(write=False)
    return a


def direction(name: str, value, n: int | None = None, *, error: type[CrosscertError] = InputError) -> np.ndarray:
    """A non-zero finite vector scaled to unit length, shape ``(n,)``, read-only."""
    a = vector(name, value, n, error=error)
    norm = float(np.linalg.norm(a))
    if norm == 0.0:
        raise error(f"{name} must be non-zero")
    out = a / norm
    out.setflags(write=False)
    return out


def floats(name: str, value, n: int | None = None, *, positive: bool = False, nonneg: bool = False,
           error: type[CrosscertError] = InputError) -> tuple[float, ...]:
    """:func:`vector` as a tuple of floats: the hashable form frozen dataclasses store."""
    return tuple(float(v) for v in vector(name, value, n, positive=positive, nonneg=nonneg, error=error))


def frozen_array(a) -> np.ndarray:
    """``a`` as a float array nobody can write (a copy when ``a`` is writable)."""
    out = np.array(a, dtype=float, copy=True)
    out.setflags(write=False)
    return out
