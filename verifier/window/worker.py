"""The online window in a process of its own (:func:`serve`, in a fresh interpreter).

:class:`~verifier.window.OnlineMonitor`'s default worker.  On a thread, the
window's Python code shares the interpreter lock with :meth:`update
<verifier.window.OnlineMonitor.update>` (measured: the update 1.7 times
slower while a window is open); in a process of its own it shares nothing.
A fresh interpreter (:mod:`subprocess`), not :mod:`multiprocessing`: a
user's script needs no ``if __name__ == "__main__"`` guard, and no thread of
the parent (numba's, BLAS's) is copied.  The compiled kernels are cached on
disk: the child loads them.

Protocol (pickled frames; the parent's on the child's stdin, the child's on its
stdout).  Parent: the setup ``(robot, settings, backend, horizon, spread, x0)``,
then ``("open", id, k, mode, start, q, x)`` when its tracker lost the mode
(the anchor and the readings so far), ``("q", id, bytes)`` readings and the
tracker's pose boxes there, ``("drop",)`` when the window closed without it,
``("settle", token)``.  Child: ``("ready",)``, then ``("decided", id, used,
lane, first, events)`` (the re-seeded lane as :meth:`Lane.export
<verifier.window.lane.Lane.export>` data, through the first ``used`` readings
of the anchor), ``("contradicted", id, used)``, ``("settled", token)`` once no
attempt is due, ``("error", exception)``.  The child stops at the end of its
stdin: the parent's :meth:`WindowProcess.close`, or the parent's death (no
orphan).
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
import weakref
from collections import deque

import numpy as np

from crosscert.robots.errors import CrosscertError

from crosscert.robots.kinematics import KinematicModel

from ..tracker import Tracker
from .lane import CONTRADICTED, FIRST_ATTEMPT, Anchor, Attempt, Reasoner, catch_up, due, next_attempt, stamps_from
from .offline import WindowStart

__all__ = ["WindowProcess", "WindowWorkerStopped", "pack_readings", "serve"]


#: Rounds of the child's catch-up over the readings that arrived during the previous one, before it sends a
#: decided lane: the first covers the attempt's time, the next ones a few samples each.
CATCH_UP_ROUNDS = 3
#: Niceness the child adds to its own: its attempts yield a busy core to the update path (measured on 2
#: shared cores: without it, the update waited milliseconds for a core while the child worked).
NICE = 10


class WindowWorkerStopped(CrosscertError):
    """The window's worker process ended (or could not start) while the monitor still needed it."""


def pack_readings(q: list, x: list, t: list | None = None) -> bytes:
    """Readings ``(n,)``, the tracker's pose boxes ``(2, n)`` there and, when the readings are stamped, their
    stamps ``t`` (s), as one frame's bytes (float64)."""
    stamps = [()] * len(q) if t is None else [(ti,) for ti in t]
    return np.concatenate([np.concatenate([qi.ravel(), xi.ravel(), ti]) for qi, xi, ti in zip(q, x, stamps)]).tobytes()


def _unpack_readings(data: bytes, n: int, stamped: bool):
    """``(q, x, t)`` of each reading :func:`pack_readings` packed (``t`` None when not ``stamped``)."""
    v = np.frombuffer(data, dtype=np.float64).reshape(-1, 3 * n + int(stamped))
    return [(row[:n].copy(), row[n:3 * n].reshape(2, n).copy(), float(row[3 * n]) if stamped else None) for row in v]


class _Inbox:
    """Frames read by a thread, for another thread to take (a deque and a condition)."""

    def __init__(self):
        self.frames = deque()
        self.cond = threading.Condition()
        self.ended = None  # why the other side stopped, once it did
        self.on_end = []

    def put(self, frame) -> None:
        with self.cond:
            self.frames.append(frame)
            self.cond.notify_all()

    def end(self, why: str) -> None:
        with self.cond:
            self.ended = self.ended or why
            self.cond.notify_all()
        for f in self.on_end:
            f()

    def take(self, block: bool) -> list:
        """Every frame waiting (at least one when ``block``)."""
        with self.cond:
            while block and not self.frames:
                self.cond.wait()
            out = list(self.frames)
            self.frames.clear()
            return out


def _read(stream, inbox: _Inbox, on_ready) -> None:
    """The parent's reader thread: frames into ``inbox`` until the child's stdout ends."""
    try:
        while True:
            frame = pickle.load(stream)
            if frame[0] == "ready":
                on_ready()
            else:
                inbox.put(frame)
    except Exception as exc:  # noqa: BLE001 - EOF, a broken pipe, a frame that does not load: the child is gone
        inbox.end(f"the window's worker process ended ({type(exc).__name__})")


def _stop(proc: subprocess.Popen, timeout: float | None) -> None:
    """End the child: its stdin closed (it exits at once, even in an attempt), killed after ``timeout`` s."""
    try:
        proc.stdin.close()
    except OSError:
        pass
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


class WindowProcess:
    """The parent's side: the child process, frames to it (:meth:`send`) and from it (:attr:`inbox`).

    Frames sent before the child is ready are kept and written then, so that the pipe never blocks
    :meth:`send` while the child starts.  A monitor dropped without :meth:`close` stops the child when
    it is collected, or at the latest when the interpreter exits.
    """

    def __init__(self, robot, settings, backend: str, horizon: int, spread: bool, x0, stamp_error=None):
        self._proc = subprocess.Popen([sys.executable, "-c", "from crosscert.verifier.window.worker import serve; serve()"],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        self.pid = self._proc.pid
        self._lock = threading.Lock()  # writes: the update path's and the reader's when the child is ready
        self._waiting = []  # frames written once the child is ready
        self._ready = False
        self.started = threading.Event()  # the child is ready, or ended
        self.inbox = _Inbox()
        self.inbox.on_end.append(self.started.set)
        self._stopper = weakref.finalize(self, _stop, self._proc, 1.0)
        self._write(pickle.dumps((robot, settings, backend, horizon, spread, x0, stamp_error)))  # small: the pipe holds it
        threading.Thread(target=_read, args=(self._proc.stdout, self.inbox, self._on_ready),
                         name="crosscert-window-reader", daemon=True).start()

    @property
    def ready(self) -> bool:
        """The child set up its model and takes frames."""
        return self._ready

    def _on_ready(self) -> None:
        with self._lock:
            self._ready = True
            for data in self._waiting:
                self._write(data)
            self._waiting = []
        self.started.set()

    def _write(self, data: bytes) -> None:
        try:
            self._proc.stdin.write(data)
            self._proc.stdin.flush()
        except (OSError, ValueError):  # the child ended: the reader says why
            self.inbox.end("the window's worker process ended")

    def send(self, frame) -> None:
        data = pickle.dumps(frame, protocol=pickle.HIGHEST_PROTOCOL)
        with self._lock:
            if self._ready:
                self._write(data)
            else:
                self._waiting.append(data)

    def close(self, timeout: float | None = None) -> None:
        """Stop the child (at once: it needs nothing more), waiting ``timeout`` s before killing it."""
        self._stopper.detach()
        _stop(self._proc, 5.0 if timeout is None else timeout)


class _Child:
    """The child's loop: the anchor the parent sent, attempts over it as readings arrive, the answers."""

    def __init__(self, reasoner: Reasoner, send, inbox: _Inbox):
        self.reasoner, self.send, self.inbox = reasoner, send, inbox
        self.anchor, self.id = None, None
        self.settling = []  # tokens of settle requests, answered once no attempt is due

    def take(self, frame) -> None:
        kind = frame[0]
        if kind == "open":
            _, self.id, k, mode, start, q, x, t = frame
            self.anchor = Anchor(k, mode, start, list(q), list(x), None if t is None else list(t))
        elif kind == "q":
            if frame[1] == self.id and self.anchor is not None:
                a = self.anchor
                for q, x, t in _unpack_readings(frame[2], self.reasoner.model.n, a.t is not None):
                    a.q.append(q)
                    a.x.append(x)
                    if a.t is not None:
                        a.t.append(t)
        elif kind == "drop":
            self.anchor = self.id = None
        elif kind == "settle":
            self.settling.append(frame[1])

    def due(self) -> bool:
        return due(self.anchor, bool(self.settling))

    def loop(self) -> None:
        while True:
            if not self.due():  # the readings so far all tried (fully, when settling): settled
                for token in self.settling:
                    self.send(("settled", token))
                self.settling = []
            for frame in self.inbox.take(block=not self.due()):
                self.take(frame)
            if not self.due():
                continue
            at = Attempt.of(None, self.anchor, *next_attempt(self.anchor, bool(self.settling)))
            h = self.reasoner.run(at)
            if h is CONTRADICTED:
                self.send(("contradicted", self.id, len(at.q)))
                self.anchor = self.id = None
            elif h is not None:
                self.decide(at, h)

    def decide(self, at: Attempt, h) -> None:
        """Re-seed from ``h`` and run the new lane over every reading there is, those that arrive meanwhile
        included, then send it (unless the parent's window closed meanwhile: the answer is moot)."""
        a, id_ = self.anchor, self.id
        new, first = self.reasoner.reseeded(at, h)
        events = catch_up(new, a.q[len(at.q) - 1:], stamps_from(a, len(at.q) - 1))
        used = len(a.q)
        for _ in range(CATCH_UP_ROUNDS):  # each round is shorter: readings keep coming, the parent does the rest
            frames = self.inbox.take(block=False)
            for frame in frames:
                self.take(frame)
            if self.anchor is not a:
                return
            events += catch_up(new, a.q[used:], stamps_from(a, used))
            used = len(a.q)
        self.send(("decided", id_, used, new.export(), first, events))
        self.anchor = self.id = None


def _warm(reasoner: Reasoner, x0) -> None:
    """Load the window's kernels from the disk cache before a window opens (most of a second, which the
    first attempt would otherwise take): a cheap and a full attempt over copies of the reading of the middle
    of the initial box ``x0`` (nominal geometry), from the rows of a tracker started at ``x0``.  Their
    answers are dropped; a failure here is the real attempts' to report."""
    try:
        robot = reasoner.model.robot
        kin = KinematicModel(robot)
        q = kin.ik((np.asarray(x0[0]) + np.asarray(x0[1])) / 2, np.asarray(robot.xi_nominal, dtype=np.float64),
                   (np.asarray(robot.q_lo, dtype=np.float64) + np.asarray(robot.q_hi, dtype=np.float64)) / 2)
        tracker = Tracker(reasoner.model, reasoner.settings, x0, backend=reasoner.backend)
        tracker.update(q)
        st = tracker.state
        live = st.row_bad < 0
        start = WindowStart(np.ascontiguousarray(st.xi[live, 0]), np.ascontiguousarray(st.xi[live, 1]),
                            st.x[live].copy(), st.xd[live].copy(), int(st.mode[0]))
        anchor = Anchor(0, int(st.mode[0]), start, [q] * FIRST_ATTEMPT, [st.x_hull[0].copy()] * FIRST_ATTEMPT)
        for full in (False, True):
            reasoner.run(Attempt.of(None, anchor, full))
    except Exception:  # noqa: BLE001 - only a warm-up
        pass


def _receive(stream, inbox: _Inbox) -> None:
    """The child's reader thread: the parent's frames; at the end of stdin the process ends at once."""
    try:
        while True:
            inbox.put(pickle.load(stream))
    except Exception:  # noqa: BLE001 - EOF (the parent closed or died) or a broken pipe: nothing more to do
        pass
    os._exit(0)


def serve() -> None:
    """The child process: set up from the first frame, then :class:`_Child`'s loop."""
    # Ctrl-C reaches the whole process group: the parent decides (it stops this process when closed)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:  # background work: when the cores are busy, the scheduler runs the update path first
        os.nice(NICE)
    except (AttributeError, OSError):
        pass
    channel = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # C-level prints go to stderr, never into the channel
    lock = threading.Lock()

    def send(frame) -> None:
        try:
            data = pickle.dumps(frame, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # noqa: BLE001 - an unpicklable answer: say so instead
            data = pickle.dumps(("error", WindowWorkerStopped(f"the window's answer could not be sent: {exc!r}")))
        with lock:
            channel.write(data)
            channel.flush()

    stream = sys.stdin.buffer
    try:
        robot, settings, backend, horizon, spread, x0, stamp_error = pickle.load(stream)
        from ..model import IntervalModel

        reasoner = Reasoner(IntervalModel(robot), settings, backend, horizon, spread, stamp_error)
        _warm(reasoner, x0)
    except EOFError:
        return
    except Exception as exc:  # noqa: BLE001 - the parent raises it on its update path
        send(("error", exc))
        return
    send(("ready",))
    inbox = _Inbox()
    threading.Thread(target=_receive, args=(stream, inbox), name="crosscert-window-receiver", daemon=True).start()
    try:
        _Child(reasoner, send, inbox).loop()
    except Exception as exc:  # noqa: BLE001 - the parent raises it on its update path
        send(("error", exc))

