"""A background worker process: ``python -m planner._worker``.

The parent writes pickled ``(module, function, args)`` frames on the worker's
stdin and reads one pickled ``(ok, value)`` frame per call on its stdout
(``value`` is the result, or the exception raised).  A fresh interpreter,
started with ``subprocess``, so that neither a user's ``__main__`` (re-run by
multiprocessing's spawn) nor inherited threads (fork) get in the way.
"""

from __future__ import annotations

import importlib
import os
import pickle
import subprocess
import sys
import threading

from robots.errors import CrosscertError


class WorkerStopped(CrosscertError):
    """The worker process ended before answering."""


def _serve() -> None:
    channel = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # solver banners and C-level prints go to stderr, never into the channel
    requests = sys.stdin.buffer
    while True:
        try:
            module, name, args = pickle.load(requests)
            value = (True, getattr(importlib.import_module(module), name)(*args))
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


class BackgroundCalls:
    """Calls of one module-level function, queued to a worker process by key.

    ``submit`` queues keys in order; ``result(key)`` waits for (queuing if
    needed) the call ``function(*args, key)``; ``drop(pred)`` removes queued
    keys not yet started; ``close`` stops the worker.
    """

    def __init__(self, module: str, name: str, args: tuple):
        self._call = (module, name, tuple(args))
        self._cond = threading.Condition()
        self._pending: list = []
        self._done: dict = {}
        self._closed = False
        self._proc = subprocess.Popen([sys.executable, "-m", "planner._worker"], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        module, name, args = self._call
        while True:
            with self._cond:
                while not self._pending and not self._closed:
                    self._cond.wait()
                if self._closed:
                    return
                key = self._pending.pop(0)
            try:
                pickle.dump((module, name, args + (key,)), self._proc.stdin)
                self._proc.stdin.flush()
                out = pickle.load(self._proc.stdout)
            except Exception as exc:  # unpicklable request or answer, dead worker: never die silently
                out = (False, WorkerStopped(f"the background worker stopped ({exc!r}); "
                                            "run without the background worker to see the error"))
            with self._cond:
                self._done[key] = out
                self._cond.notify_all()
                if not out[0] and isinstance(out[1], WorkerStopped):
                    self._closed = True
                    return

    def submit(self, keys) -> None:
        with self._cond:
            for k in keys:
                if k not in self._done and k not in self._pending:
                    self._pending.append(k)
            self._cond.notify_all()

    def drop(self, pred) -> None:
        with self._cond:
            self._pending = [k for k in self._pending if not pred(k)]

    def result(self, key):
        self.submit([key])
        with self._cond:
            while key not in self._done:
                if self._closed:
                    raise WorkerStopped("the background worker stopped; run without the background worker")
                self._cond.wait()
            ok, value = self._done[key]
        if not ok:
            raise value
        return value

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._pending.clear()
            self._cond.notify_all()
        if self._proc.poll() is None:
            self._proc.kill()  # a search still running is not needed any more
        self._proc.wait()
        self._thread.join()
        for f in (self._proc.stdin, self._proc.stdout):
            try:
                f.close()
            except OSError:
                pass


if __name__ == "__main__":
    _serve()
