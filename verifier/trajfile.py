"""Trajectory files: what ``crosscert check`` reads and ``crosscert simulate`` writes.

Format (CSV, comma-separated, one header row):

* ``t`` — sample time, s, strictly increasing with a constant step ``t_s``
  (the tracker's prediction assumes one fixed sampling period);
* ``q1 .. qn`` — encoder readings, rad;
* optional ``qd1 .. qdn`` — joint velocities, rad/s (accepted, checked, not
  used: the tracker derives velocity information from the positions, whose
  error bound it knows);
* optional ``x1 .. xn`` — planned end-effector pose, SI (written by
  ``crosscert plan``; accepted, checked, used only for plots).

Any other column, a missing column, a non-numeric, NaN or infinite value is
an error (:class:`~verifier.errors.TrajectoryFileError`).
"""

from __future__ import annotations

import csv
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import TrajectoryFileError

__all__ = ["Trajectory", "read_trajectory", "write_trajectory", "TIME_STEP_RTOL"]

#: Relative tolerance on the sampling step (time stamps written in decimal).
TIME_STEP_RTOL = 1e-6


@dataclass(frozen=True)
class Trajectory:
    """A recorded joint trajectory.

    Attributes
    ----------
    t : array (K,)
        Sample times, s.
    q : array (K, n)
        Encoder readings, rad.
    qd : array (K, n) or None
        Joint velocities, rad/s, when the file has them.
    x : array (K, n) or None
        Planned poses, SI, when the file has them.
    t_s : float
        Sampling period, s.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray | None
    t_s: float
    x: np.ndarray | None = None


def read_trajectory(path, n: int) -> Trajectory:
    """Read and validate a trajectory file for a robot with ``n`` joints.

    Raises
    ------
    TrajectoryFileError
        With a message naming the file, the line and what is wrong.
    """
    path = Path(path)
    if not path.is_file():
        raise TrajectoryFileError(f"{path}: no such file")
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise TrajectoryFileError(f"{path}: cannot read as CSV ({exc})") from None
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise TrajectoryFileError(f"{path}: empty file (expected a header t,q1..q{n})")
    header = [c.strip() for c in rows[0]]
    qcols = [f"q{i + 1}" for i in range(n)]
    qdcols = [f"qd{i + 1}" for i in range(n)]
    xcols = [f"x{i + 1}" for i in range(n)]
    missing = [c for c in ["t"] + qcols if c not in header]
    if missing:
        raise TrajectoryFileError(f"{path}: missing column(s) {', '.join(missing)}; expected t,{','.join(qcols)}[,{','.join(qdcols)}]")
    extra = [c for c in header if c not in ["t"] + qcols + qdcols + xcols]
    if extra:
        raise TrajectoryFileError(
            f"{path}: unexpected column(s) {', '.join(extra)}; expected t,{','.join(qcols)}"
            f"[,{','.join(qdcols)}][,{','.join(xcols)}]"
        )
    if len(set(header)) != len(header):
        raise TrajectoryFileError(f"{path}: duplicated column names in the header")
    has_qd = any(c in header for c in qdcols)
    for group in (qdcols, xcols):
        if any(c in header for c in group) and not all(c in header for c in group):
            raise TrajectoryFileError(f"{path}: give all of {','.join(group)} or none")
    has_x = xcols[0] in header
    data = np.empty((len(rows) - 1, len(header)))
    for i, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise TrajectoryFileError(f"{path}, line {i}: {len(row)} values for {len(header)} columns")
        for j, cell in enumerate(row):
            try:
                data[i - 2, j] = float(cell)
            except ValueError:
                raise TrajectoryFileError(f"{path}, line {i}: {cell.strip()!r} in column {header[j]} is not a number") from None
    bad = ~np.isfinite(data)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise TrajectoryFileError(f"{path}, line {i + 2}: column {header[j]} is {data[i, j]} (NaN and infinities are not allowed)")
    if len(data) < 2:
        raise TrajectoryFileError(f"{path}: at least two samples are needed, got {len(data)}")
    t = data[:, header.index("t")]
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise TrajectoryFileError(f"{path}, line {i + 3}: time {t[i + 1]} does not increase (previous {t[i]}); the tracker needs strictly increasing times")
    t_s = float((t[-1] - t[0]) / (len(t) - 1))
    uneven = np.abs(dt - t_s) > TIME_STEP_RTOL * t_s
    if uneven.any():
        i = int(np.argmax(uneven))
        raise TrajectoryFileError(
            f"{path}, line {i + 3}: uneven sampling (step {dt[i]:.9g} s, mean {t_s:.9g} s); "
            "the tracker assumes one constant sampling period: resample or split the file"
        )
    q = data[:, [header.index(c) for c in qcols]]
    qd = data[:, [header.index(c) for c in qdcols]] if has_qd else None
    x = data[:, [header.index(c) for c in xcols]] if has_x else None
    return Trajectory(t=t, q=q, qd=qd, t_s=t_s, x=x)


def write_trajectory(path, t, q, qd=None, x=None) -> None:
    """Write a trajectory file atomically (a partial file is never left behind).

    ``t`` (K,) s, ``q`` (K, n) rad, optional ``qd`` (K, n) rad/s and planned
    poses ``x`` (K, n) SI.
    """
    path = Path(path)
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    n = q.shape[1]
    cols = ["t"] + [f"q{i + 1}" for i in range(n)]
    data = [t[:, None], q]
    if qd is not None:
        cols += [f"qd{i + 1}" for i in range(n)]
        data.append(np.asarray(qd, dtype=float))
    if x is not None:
        cols += [f"x{i + 1}" for i in range(n)]
        data.append(np.asarray(x, dtype=float))
    arr = np.hstack(data)
    directory = path.parent if str(path.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=directory)
    try:
        with os.fdopen(fd, "w", newline="") as fh:
            fh.write(",".join(cols) + "\n")
            for row in arr:
                fh.write(",".join(repr(float(v)) for v in row) + "\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
