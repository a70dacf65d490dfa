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
an error (:class:`~robots.errors.TrajectoryFileError`).
:func:`read_trajectory` reads a whole file (the period is the mean step);
:class:`TrajectoryReader` reads a stream line by line (``crosscert monitor``;
the period is given or fixed by the first step).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from robots.errors import TrajectoryFileError

from .files import atomic_write
from .trajectory import Trajectory

__all__ = ["Trajectory", "TrajectoryReader", "read_trajectory", "write_trajectory", "TIME_STEP_RTOL"]

#: Relative tolerance on the sampling step (time stamps written in decimal).
TIME_STEP_RTOL = 1e-6


class TrajectoryReader:
    """Read a trajectory CSV one sample at a time, validating each line as it comes.

    The header is read at the first iteration; then each non-blank line is
    parsed and checked (cell count, numbers, finite values, increasing time,
    and with ``even`` the step) when it is read, so a stream (a pipe, stdin)
    is processed sample by sample.

    Parameters
    ----------
    stream : text stream
        Open for reading, ideally with ``newline=""``.
    n : int
        Number of joints of the robot.
    name : str
        Names the source in error messages.
    t_s : float, optional
        Expected sampling period, s; ``None``: the first step fixes it.
    even : bool
        Check every step against ``t_s`` (within :data:`TIME_STEP_RTOL`) as it
        is read; :func:`read_trajectory` checks against the mean step instead.

    Attributes
    ----------
    header : list of str
        Column names, once read.
    t_s : float or None
        Sampling period, once known.
    line : int
        Number of the last line read (non-blank rows, the header being line 1).

    Raises
    ------
    TrajectoryFileError
        While iterating, with a message naming the source, the line and what is wrong.
    """

    def __init__(self, stream, n: int, name, *, t_s: float | None = None, even: bool = True):
        self.name, self.n, self.t_s, self.even = str(name), n, t_s, even
        self.header = None
        self.line = 0
        self._rows = csv.reader(stream)
        self._cols = {"q": [f"q{i + 1}" for i in range(n)], "qd": [f"qd{i + 1}" for i in range(n)],
                      "x": [f"x{i + 1}" for i in range(n)]}

    def _next_row(self):
        """The next non-blank row, or None at the end."""
        try:
            for row in self._rows:
                if any(c.strip() for c in row):
                    self.line += 1
                    return row
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise TrajectoryFileError(f"{self.name}: cannot read as CSV ({exc})") from None
        return None

    def _error(self, message):
        return TrajectoryFileError(f"{self.name}, line {self.line}: {message}")

    def _read_header(self):
        row = self._next_row()
        qcols, qdcols, xcols = self._cols["q"], self._cols["qd"], self._cols["x"]
        if row is None:
            raise TrajectoryFileError(f"{self.name}: empty file (expected a header t,q1..q{self.n})")
        header = [c.strip() for c in row]
        missing = [c for c in ["t"] + qcols if c not in header]
        if missing:
            raise TrajectoryFileError(f"{self.name}: missing column(s) {', '.join(missing)}; "
                                      f"expected t,{','.join(qcols)}[,{','.join(qdcols)}]")
        extra = [c for c in header if c not in ["t"] + qcols + qdcols + xcols]
        if extra:
            raise TrajectoryFileError(
                f"{self.name}: unexpected column(s) {', '.join(extra)}; expected t,{','.join(qcols)}"
                f"[,{','.join(qdcols)}][,{','.join(xcols)}]"
            )
        if len(set(header)) != len(header):
            raise TrajectoryFileError(f"{self.name}: duplicated column names in the header")
        for group in (qdcols, xcols):
            if any(c in header for c in group) and not all(c in header for c in group):
                raise TrajectoryFileError(f"{self.name}: give all of {','.join(group)} or none")
        self.header = header

    def _parse(self, row):
        header = self.header
        if len(row) != len(header):
            raise self._error(f"{len(row)} values for {len(header)} columns")
        values = np.empty(len(header))
        for j, cell in enumerate(row):
            try:
                values[j] = float(cell)
            except ValueError:
                raise self._error(f"{cell.strip()!r} in column {header[j]} is not a number") from None
            if not np.isfinite(values[j]):
                raise self._error(f"column {header[j]} is {values[j]} (NaN and infinities are not allowed)")
        return values

    def check_step(self, t_prev: float, t: float, t_s: float, line: int, what: str = "sampling period") -> None:
        """Raise unless the step ``t - t_prev`` ending on ``line`` is within ``TIME_STEP_RTOL * t_s`` of ``t_s``."""
        if abs((t - t_prev) - t_s) > TIME_STEP_RTOL * t_s:
            raise TrajectoryFileError(
                f"{self.name}, line {line}: uneven sampling (step {t - t_prev:.9g} s, {what} {t_s:.9g} s); "
                "the tracker assumes one constant sampling period: resample or split the file"
            )

    def __iter__(self):
        """Yield ``(line, values)``: the line number and its values in header order (array)."""
        if self.header is None:
            self._read_header()
        it = self.header.index("t")
        t_prev = None
        while (row := self._next_row()) is not None:
            values = self._parse(row)
            t = values[it]
            if t_prev is not None:
                if not t > t_prev:
                    raise self._error(f"time {t} does not increase (previous {t_prev}); "
                                      "the tracker needs strictly increasing times")
                if self.even:
                    if self.t_s is None:
                        self.t_s = float(t - t_prev)
                    self.check_step(t_prev, t, self.t_s, self.line)
            yield self.line, values
            t_prev = t

    def columns(self, values):
        """Split values in header order, one row ``(C,)`` or rows ``(K, C)``, into ``t, q, qd, x`` (``None`` when absent)."""
        h = self.header
        pick = lambda cols: values[..., [h.index(c) for c in cols]] if cols[0] in h else None  # noqa: E731
        return values[..., h.index("t")], pick(self._cols["q"]), pick(self._cols["qd"]), pick(self._cols["x"])


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
            reader = TrajectoryReader(fh, n, path, even=False)
            samples = list(reader)
    except OSError as exc:
        raise TrajectoryFileError(f"{path}: cannot read as CSV ({exc})") from None
    if len(samples) < 2:
        raise TrajectoryFileError(f"{path}: at least two samples are needed, got {len(samples)}")
    t, q, qd, x = reader.columns(np.array([v for _, v in samples]))
    t_s = float((t[-1] - t[0]) / (len(t) - 1))
    for i in np.flatnonzero(np.abs(np.diff(t) - t_s) > TIME_STEP_RTOL * t_s)[:1] + 1:  # the first uneven step
        reader.check_step(t[i - 1], t[i], t_s, samples[i][0], "mean")
    return Trajectory(t=t, q=q, qd=qd, t_s=t_s, x=x)


def write_trajectory(path, t, q, qd=None, x=None) -> None:
    """Write a trajectory file with :func:`verifier.files.atomic_write` (never a partial file).

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

    def fill(fh):
        fh.write(",".join(cols) + "\n")
        for row in arr:
            fh.write(",".join(repr(float(v)) for v in row) + "\n")

    atomic_write(path, fill)
