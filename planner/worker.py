"""A one-process executor with the ``concurrent.futures`` interface: ``python -m planner.worker``.

:class:`SubprocessExecutor` runs calls, in the order they were submitted, in
one fresh interpreter started with :mod:`subprocess`.  It exists beside
``ProcessPoolExecutor`` because a user's script is often not guarded by
``if __name__ == "__main__"``: multiprocessing's ``spawn`` and ``forkserver``
re-import it in the child, and ``fork`` copies the parent's threads (numba's
and BLAS's) into it.  A fresh interpreter sees neither.  Any other executor
(a thread pool, a process pool, a Dask client's ``get_executor()``) can be
passed wherever this one is the default.

Protocol: the parent writes pickled ``(function, args, kwargs)`` frames on the
child's stdin and reads one pickled ``(ok, value)`` frame per call on its stdout.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
from concurrent.futures import Executor, Future

from crosscert.robots.errors import CrosscertError

__all__ = ["SubprocessExecutor", "WorkerStopped"]


class WorkerStopped(CrosscertError):
    """The worker process ended before answering."""


def serve() -> None:
    """The child's loop: answer every frame read on stdin until it closes."""
    # Ctrl-C reaches the whole process group: the parent decides (it kills this process when the
    # result is no longer wanted), so that a search never half-ends on its own
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    channel = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # solver banners and C-level prints go to stderr, never into the channel
    requests = sys.stdin.buffer
    while True:
        try:
            fn, args, kwargs = pickle.load(requests)
            value = (True, fn(*args, **kwargs))
        except EOFError:
            return
        except Exception as exc:  # sent back and re-raised by the parent
            value = (False, exc)
        try:
            data = pickle.dumps(value)
        except Exception as exc:  # an unpicklable result or exception: say so instead
            data = pickle.dumps((False, RuntimeError(f"worker result could not be sent back: {exc!r}; "
                                                     f"it was {value[1]!r}")))
        channel.write(data)
        channel.flush()


class SubprocessExecutor(Executor):
    """Calls run one at a time, in submission order, in one fresh Python process.

    ``submit(fn, *args, **kwargs)`` returns a :class:`~concurrent.futures.Future`;
    ``fn`` and its arguments must be picklable (a module-level function of an
    importable module).  A future not yet started can be cancelled.  When the
    process dies, the running call and every later one fail with
    :class:`WorkerStopped`.  ``shutdown`` kills a call still running: its
    result is no longer wanted.
    """

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._queue: list[tuple[Future, bytes | None, BaseException | None]] = []
        self._stopped: str | None = None
        self._shutdown = False
        self._proc = subprocess.Popen([sys.executable, "-m", "crosscert.planner.worker"], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        self._thread = threading.Thread(target=self._loop, name="crosscert-worker", daemon=True)
        self._thread.start()

    def submit(self, fn, /, *args, **kwargs) -> Future:
        future: Future = Future()
        try:
            frame, error = pickle.dumps((fn, args, kwargs)), None
        except Exception as exc:  # fails this call only; the worker goes on
            frame, error = None, exc
        with self._cond:
            if self._shutdown:
                raise RuntimeError("cannot submit to a SubprocessExecutor after shutdown")
            self._queue.append((future, frame, error))
            self._cond.notify_all()
        return future

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._shutdown:
                    self._cond.wait()
                if not self._queue:
                    return
                future, frame, error = self._queue.pop(0)
                stopped = self._stopped
            if not future.set_running_or_notify_cancel():
                continue
            if stopped is not None:
                future.set_exception(WorkerStopped(stopped))
            elif error is not None:
                future.set_exception(error)
            else:
                self._call(future, frame)

    def _call(self, future: Future, frame: bytes) -> None:
        try:
            self._proc.stdin.write(frame)
            self._proc.stdin.flush()
            ok, value = pickle.load(self._proc.stdout)
        except Exception as exc:  # a dead worker: never die silently
            with self._cond:
                self._stopped = (f"the background worker stopped ({exc!r}); "
                                 "run without the background worker to see the error")
            future.set_exception(WorkerStopped(self._stopped))
            return
        if ok:
            future.set_result(value)
        else:
            future.set_exception(value)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop accepting calls; with ``wait`` run what is queued first, else kill a call still running."""
        with self._cond:
            self._shutdown = True
            if cancel_futures:
                for future, _, _ in self._queue:
                    future.cancel()
            self._cond.notify_all()
        if not wait and self._proc.poll() is None:
            self._proc.kill()  # a search still running is not needed any more
        self._thread.join()
        for f in (self._proc.stdin, self._proc.stdout):
            try:
                f.close()  # the child reads EOF and exits
            except OSError:
                pass
        self._proc.wait()


if __name__ == "__main__":
    serve()
