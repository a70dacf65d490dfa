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
the period is given or fixed by the first step).  Its time checks (increasing
stamps, a constant step, the joint range) live in :class:`SampleReader`, the
one validator every recording format passes through (the ROS 2 bags and
``.npz`` files of :mod:`verifier.recordings` too).
"""

from __future__ import annotations

import contextlib
import csv
import re
import sys
from pathlib import Path

import numpy as np

from crosscert.robots.errors import TrajectoryFileError

from .clock import JITTER_RTOL, STAMP_ULPS, TIME_STEP_RTOL, SampleClock, step_tolerance
from .files import atomic_write
from .trajectory import Trajectory

__all__ = ["Trajectory", "SampleReader", "TrajectoryReader", "open_trajectory", "checked_path", "read_trajectory", "write_trajectory",
           "step_tolerance", "parse_number", "TIME_STEP_RTOL", "STAMP_ULPS"]

#: What a reading error adds when the data start with the gzip magic bytes.
GZIP_HINT = " (the data look gzip-compressed: decompress them first, e.g. zcat FILE.gz | crosscert monitor -)"
#: Rows read per block by :func:`read_trajectory` (memory grows by blocks, not rows).
_BLOCK_ROWS = 65536
#: A number as a CSV cell may write it: ASCII digits, optional sign, point and
#: exponent; no digit separators (``1_0``), no other scripts' digits, no words (``nan``).
_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?", re.ASCII)


def parse_number(text: str) -> float:
    """The float a CSV cell or an option writes, or ValueError: ASCII decimal notation only.

    Python's ``float`` also takes ``1_0.5``, Arabic-Indic digits, ``nan`` and
    ``infinity``; a recording or an option holding those is a mistake to
    report, not a number to guess.
    """
    t = text.strip()
    if not _NUMBER.fullmatch(t):
        raise ValueError(f"{text!r} is not a decimal number")
    return float(t)


def _unit_hint(step: float, t_s: float) -> str:
    """`` (times in ms?)`` when ``step`` is ``t_s`` written in ms or us, else an empty string."""
    for factor, unit in ((1e3, "ms"), (1e6, "us")):
        if abs(step - factor * t_s) <= 1e-6 * factor * t_s:
            return f" (the time column seems to be in {unit}: convert it to seconds)"
    return ""


def checked_path(path, *, folder: bool = False) -> Path:
    """``path`` as a Path when it names a recording that exists (a folder only when ``folder``).

    Raises
    ------
    TrajectoryFileError
        For a missing path, or a directory where a file is expected.
    """
    p = Path(path)
    if p.is_dir() and not folder:
        raise TrajectoryFileError(f"{p}: is a directory, not a recording")
    if not p.exists():
        raise TrajectoryFileError(f"{p}: no such file")
    return p


@contextlib.contextmanager
def open_trajectory(path):
    """The text stream of a recording: a file, a named pipe, or stdin for ``-``.

    Opened as UTF-8 with an optional byte-order mark; yields ``(stream, name)``.

    Raises
    ------
    TrajectoryFileError
        For a missing path, a directory, or a file that cannot be opened.
    """
    if str(path) == "-":
        yield sys.stdin, "<stdin>"
        return
    p = checked_path(path)
    try:
        fh = p.open(newline="", encoding="utf-8-sig")
    except OSError as exc:
        raise TrajectoryFileError(f"{p}: cannot open ({exc.strerror})") from None
    with fh:
        yield fh, str(p)


class SampleReader:
    """The checks every recording's samples pass, whatever its format: the one validator of their times.

    A format yields ``(position, t, q, values)`` from :meth:`_records` (its
    position: a CSV's line, a bag's message, an array's index; ``t`` in s;
    ``q`` (n,) in the joints' units, both finite: the format checks its
    values; ``values`` what the format wants back); :meth:`samples` yields
    them as ``(position, t, q)`` once checked: strictly increasing times,
    with ``even`` every step against ``t_s`` (within :func:`step_tolerance`),
    and the joint range, each as it is read, so that a stream is processed
    sample by sample.

    Parameters
    ----------
    n : int
        Number of joints of the robot.
    name : str
        Names the source in error messages.
    t_s : float, optional
        Expected sampling period, s; ``None``: the first step fixes it (the
        robot's ``nominal_t_s`` when the first step matches it within
        :func:`step_tolerance`).
    even : bool
        Check every step against ``t_s`` (within :func:`step_tolerance`) as it
        is read; :func:`read_trajectory` checks against the mean step instead.
    nominal_t_s : float, optional
        The robot's sampling period, s: a recording whose period differs gets a warning.
    stamp_error : float, optional
        The stamps' error bound, s (``--stamp-error``): an uneven recording is
        read, its steps checked by a :class:`~verifier.clock.SampleClock`
        (:attr:`clock`; dropped samples of a fixed period with 0, jittered
        stamps with more).  None: every step must be ``t_s``.
    q_range : (lo, hi) arrays (n,), optional
        The robot's joint range, rad: the first sample outside it gets a warning.

    Attributes
    ----------
    t_s : float or None
        Sampling period, once known.
    line : int
        Position of the last sample read (for a CSV, its line: non-blank rows, the header being line 1).
    warnings : list of str
        What was odd but not wrong (period off the robot's, joints out of range).

    Raises
    ------
    TrajectoryFileError
        While iterating, with a message naming the source, the position and what is wrong.
    """

    #: What a position is called in messages.
    where = "line"
    #: The advice for imprecise stamps of a fixed period: how to write them again, readings unchanged.
    restamp = "re-stamp the time column at it (t_k = t_0 + k t_s, readings unchanged)"
    #: What a format adds to the clock's refusal of a step (another stamp to read, ...).
    uneven_hint = ""

    def __init__(self, n: int, name, *, t_s: float | None = None, even: bool = True,
                 nominal_t_s: float | None = None, q_range=None, stamp_error: float | None = None):
        self.name, self.n, self.t_s, self.even = str(name), n, t_s, even
        self.nominal_t_s, self.q_range = nominal_t_s, q_range
        self.stamp_error = None if stamp_error is None else float(stamp_error)
        self.clock = None  # with a stamp error: the samples' times, checked by it (verifier.clock)
        self.line = 0
        self.warnings: list[str] = []
        self._out_of_range = False

    def _records(self):
        """Yield ``(position, t, q, values)``, one per sample, in the order read (the format's part)."""
        raise NotImplementedError

    def _order_hint(self) -> str:
        """What to add when the times do not increase (a format's likely cause)."""
        return ""

    def _error(self, message):
        return TrajectoryFileError(f"{self.name}, {self.where} {self.line}: {message}")

    def _check_range(self, q) -> None:
        if self.q_range is None or self._out_of_range:
            return
        lo, hi = self.q_range
        bad = np.flatnonzero((q < lo) | (q > hi))
        if bad.size:
            self._out_of_range = True
            j = int(bad[0])
            self.warnings.append(f"{self.name}, {self.where} {self.line}: q{j + 1} = {q[j]:.6g} rad is outside the "
                                 f"robot's joint range [{lo[j]:.6g}, {hi[j]:.6g}] rad (first such sample; are the "
                                 "units rad?)")

    def _first_step(self, t_prev: float, t: float, line: int) -> None:
        """Fix ``t_s`` from the first step: the nominal period when it matches, with a warning when not."""
        step, nominal = float(t - t_prev), self.nominal_t_s
        if nominal is not None and abs(step - nominal) <= step_tolerance(t_prev, t, nominal):
            self.t_s = float(nominal)  # the controller's period, not a stamp difference rounded at 1.7e9 s
            return
        if nominal is not None and abs(step - nominal) <= JITTER_RTOL * nominal:
            self.t_s = float(nominal)  # imprecise stamps of the nominal period: check_step says how to re-stamp
            return
        self.t_s = step
        if nominal is not None:
            self.warnings.append(f"{self.name}, {self.where} {line}: sampling period {step:.9g} s differs from the "
                                 f"robot's nominal {nominal:.9g} s (the first step of the time column)"
                                 + _unit_hint(step, nominal)
                                 + f"; if {step:.9g} s is right, pass --t-s {step:.9g} to state it")

    def _stated_step(self, t_prev: float, t: float, line: int) -> None:
        """The first step against the period the caller stated (``--t-s``): a file sampled at another period is
        said to be so, not reported as uneven."""
        step = float(t - t_prev)
        if abs(step - self.t_s) > step_tolerance(t_prev, t, self.t_s) and abs(step - self.t_s) > JITTER_RTOL * self.t_s:
            raise self._error(f"the file's step is {step:.9g} s, --t-s says {self.t_s:.9g} s"
                              + _unit_hint(step, self.t_s)
                              + ": drop --t-s to read the period from the file, or correct it")

    def check_step(self, t_prev: float, t: float, t_s: float, line: int, what: str = "sampling period") -> None:
        """Raise unless the step ``t - t_prev`` ending at position ``line`` is within :func:`step_tolerance` of ``t_s``.

        The advice never is to resample: interpolated readings are no longer
        within ``eps_q`` of the true joints.  Stamps that are merely imprecise
        (float32, clock jitter) are read with their error bound
        (``--stamp-error``), or re-stamped at the nominal period (:attr:`restamp`).
        """
        step = t - t_prev
        if abs(step - t_s) > step_tolerance(t_prev, t, t_s):
            unit = _unit_hint(step, t_s)
            if unit:
                advice = f"{unit}; the time column is read in s"
            elif abs(step - t_s) <= JITTER_RTOL * t_s:
                advice = (f"; the steps differ by {abs(step - t_s):.3g} s only (float32 stamps or clock jitter?): "
                          "state the stamps' error bound with --stamp-error (s), or, if the samples were taken at a "
                          f"fixed period, {self.restamp}; never resample the readings")
            else:
                advice = ("; this reader needs one constant sampling period: split the recording where the period "
                          "changes, or track it with crosscert check, which reads dropped samples and jittered "
                          "stamps (--stamp-error); do not resample: interpolated readings break the eps_q bound")
            raise TrajectoryFileError(
                f"{self.name}, {self.where} {line}: uneven sampling (step {step:.9g} s, {what} {t_s:.9g} s){advice}")

    def _validated(self):
        """The records of :meth:`_records`, each checked as it is read."""
        t_prev = None
        first = True  # the first step: checked against a stated period with its own message
        for line, t, q, values in self._records():
            self.line = line
            self._check_range(q)
            if t_prev is not None:
                if not t > t_prev:
                    raise self._error(f"time {t} does not increase (previous {t_prev}); "
                                      "the tracker needs strictly increasing times" + self._order_hint())
                if self.even:
                    if self.t_s is None:
                        self._first_step(t_prev, t, line)
                    elif first:
                        self._stated_step(t_prev, t, line)
                    if self.stamp_error is None or _unit_hint(t - t_prev, self.t_s):
                        self.check_step(t_prev, t, self.t_s, line)
                    else:
                        self._clocked(t_prev, t, line)
                first = False
            yield line, t, q, values
            t_prev = t

    def _clocked(self, t_prev: float, t: float, line: int) -> None:
        """Steps of whole periods (dropped samples) or, with a positive stamp error, any positive ones:
        :class:`~verifier.clock.SampleClock` checks each as it is read."""
        try:
            if self.clock is None:
                self.clock = SampleClock(self.t_s, self.stamp_error, name=self.name)
                self.clock.append(t_prev, where="the first sample")
            self.clock.append(t, where=f"{self.where} {line}")
        except TrajectoryFileError as exc:
            restamp = f"; or, if the samples were taken every period, {self.restamp}" if self.stamp_error == 0 else ""
            raise TrajectoryFileError(f"{exc}{restamp}{self.uneven_hint}") from None

    def samples(self):
        """Yield ``(position, t, q)``: where the sample was read, its time (s) and readings ``(n,)``, checked."""
        for line, t, q, _ in self._validated():
            yield line, t, q


class TrajectoryReader(SampleReader):
    """Read a trajectory CSV one sample at a time, validating each line as it comes.

    The header is read at the first iteration; then each non-blank line is
    parsed and checked (cell count, numbers, finite values) and its time
    checked by :class:`SampleReader` when it is read, so a stream (a pipe,
    stdin) is processed sample by sample.

    Parameters
    ----------
    stream : text stream
        Open for reading, ideally with ``newline=""``.
    n, name, t_s, even, nominal_t_s, q_range
        As for :class:`SampleReader`.

    Attributes
    ----------
    header : list of str
        Column names, once read.
    t_s, line, warnings
        As for :class:`SampleReader`.

    Raises
    ------
    TrajectoryFileError
        While iterating, with a message naming the source, the line and what is wrong.
    """

    def __init__(self, stream, n: int, name, *, t_s: float | None = None, even: bool = True,
                 nominal_t_s: float | None = None, q_range=None, stamp_error: float | None = None):
        super().__init__(n, name, t_s=t_s, even=even, nominal_t_s=nominal_t_s, q_range=q_range,
                         stamp_error=stamp_error)
        self.header = None
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
        except UnicodeDecodeError as exc:
            hint = GZIP_HINT if bytes(exc.object[:2]) == b"\x1f\x8b" else " (not UTF-8 text: is it a CSV file?)"
            raise TrajectoryFileError(f"{self.name}: cannot read as CSV ({exc}){hint}") from None
        except (OSError, csv.Error) as exc:
            raise TrajectoryFileError(f"{self.name}: cannot read as CSV ({exc})") from None
        return None

    def _read_header(self):
        row = self._next_row()
        qcols, qdcols, xcols = self._cols["q"], self._cols["qd"], self._cols["x"]
        if row is None:
            raise TrajectoryFileError(f"{self.name}: empty file (expected a header t,q1..q{self.n})")
        header = [c.strip() for c in row]
        header[0] = header[0].lstrip("\ufeff")  # a byte-order mark read through a stream that kept it
        missing = [c for c in ["t"] + qcols if c not in header]
        if missing:
            raise TrajectoryFileError(f"{self.name}: missing column(s) {', '.join(missing)}; "
                                      f"expected t,{','.join(qcols)}[,{','.join(qdcols)}]{self._header_hint(row)}")
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

    def _header_hint(self, row) -> str:
        """Why a first row is no header: compressed data, a comment line, upper-case names, another separator."""
        text = ",".join(row)
        if text[:1] == "\x1f" and text[1:2] in ("\x8b", "\udc8b", "\ufffd"):
            return GZIP_HINT
        if "\x00" in text or "\ufffd" in text or any("\udc80" <= c <= "\udcff" for c in text):
            return " (the data are not text: is it a CSV file?)"
        if text.lstrip().startswith("#"):
            return (" (line 1 starts with '#': comment lines are not read; remove them, e.g. grep -v '^#', so that "
                    "the header is the first line)")
        names = [c.strip() for c in row]
        wanted = {"t", *self._cols["q"], *self._cols["qd"], *self._cols["x"]}
        if any(c.lower() in wanted and c not in wanted for c in names):
            return " (column names are lower-case: t, q1, q2, ...; rename the header's columns)"
        return self._delimiter_hint(row)

    @staticmethod
    def _delimiter_hint(row) -> str:
        text = ",".join(row)
        for sep, name in ((";", "semicolons"), ("\t", "tabs")):
            if sep in text:
                return (f" (the file seems to separate values with {name}: crosscert reads comma-separated "
                        "values with '.' as the decimal mark)")
        return ""

    def _parse(self, row):
        header = self.header
        if len(row) != len(header):
            hint = self._delimiter_hint(row)
            if not hint and len(row) > len(header):
                hint = " (a decimal comma? crosscert reads '.' as the decimal mark and ',' between values)"
            raise self._error(f"{len(row)} values for {len(header)} columns{hint}")
        values = np.empty(len(header))
        for j, cell in enumerate(row):
            if cell.strip().lower().lstrip("+-") in ("nan", "inf", "infinity"):
                raise self._error(f"column {header[j]} is {cell.strip()} (NaN and infinities are not allowed)")
            try:
                values[j] = parse_number(cell)
            except ValueError:
                raise self._error(f"{cell.strip()!r} in column {header[j]} is not a number") from None
            if not np.isfinite(values[j]):
                raise self._error(f"column {header[j]} is {values[j]} (NaN and infinities are not allowed)")
        return values

    def _records(self):
        if self.header is None:
            self._read_header()
        it = self.header.index("t")
        iq = [self.header.index(c) for c in self._cols["q"]]
        while (row := self._next_row()) is not None:
            values = self._parse(row)
            yield self.line, values[it], values[iq], values

    def __iter__(self):
        """Yield ``(line, values)``: the line number and its values in header order (array)."""
        for line, _, _, values in self._validated():
            yield line, values

    def columns(self, values):
        """Split values in header order, one row ``(C,)`` or rows ``(K, C)``, into ``t, q, qd, x`` (``None`` when absent)."""
        h = self.header
        pick = lambda cols: values[..., [h.index(c) for c in cols]] if cols[0] in h else None  # noqa: E731
        return values[..., h.index("t")], pick(self._cols["q"]), pick(self._cols["qd"]), pick(self._cols["x"])


def read_trajectory(path, n: int, *, nominal_t_s: float | None = None) -> Trajectory:
    """Read and validate a whole trajectory file (or ``-``, stdin) for a robot with ``n`` joints.

    The period is the mean step, or ``nominal_t_s`` when the mean step matches
    it within :func:`step_tolerance`.  Memory is the array of values (read in
    blocks of rows); to track a recording in constant memory, iterate a
    :class:`TrajectoryReader` instead (as ``crosscert check`` does).

    Raises
    ------
    TrajectoryFileError
        With a message naming the file, the line and what is wrong.
    """
    blocks, first_line, rows = [], None, 0
    with open_trajectory(path) as (fh, name):
        reader = TrajectoryReader(fh, n, name, even=False)
        block = None
        for line, values in reader:
            if block is None or rows == block.shape[0]:
                block, rows = np.empty((_BLOCK_ROWS, values.size)), 0
                blocks.append(block)
            block[rows] = values
            rows += 1
            first_line = line if first_line is None else first_line
    if blocks:
        blocks[-1] = blocks[-1][:rows]
    data = np.concatenate(blocks) if blocks else np.empty((0, 0))
    if data.shape[0] < 2:
        raise TrajectoryFileError(f"{name}: at least two samples are needed, got {data.shape[0]}")
    t, q, qd, x = reader.columns(data)
    t_s = float((t[-1] - t[0]) / (len(t) - 1))
    if nominal_t_s is not None and abs(t_s - nominal_t_s) <= step_tolerance(t[0], t[-1], nominal_t_s):
        t_s = float(nominal_t_s)
    tol = TIME_STEP_RTOL * t_s + STAMP_ULPS * np.spacing(np.maximum(np.abs(t[:-1]), np.abs(t[1:])))
    for i in np.flatnonzero(np.abs(np.diff(t) - t_s) > tol)[:1] + 1:  # the first uneven step
        # line numbers count non-blank rows, so row i is on line first_line + i
        reader.check_step(t[i - 1], t[i], t_s, first_line + int(i), "mean")
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
