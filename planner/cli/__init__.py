"""The ``crosscert`` command: certify a planned crossing, plan one, check a recording, monitor a stream,
simulate, sweep, run a design study, list and validate robots.

Exit codes: 0 a verdict was given, 2 bad input or usage (one line on stderr,
no traceback), 3 the data contradict the assumptions (inconsistent), 130
interrupted (Ctrl-C), 141 the reader of the standard output went away (a
closed pipe, as in ``crosscert monitor ... | head -1``: a quiet end, as
``cat`` under ``set -o pipefail``).  Robots come from :mod:`robots.registry`;
every command takes ``--robot`` (a name, or a robot file ``path.py:NAME``).
"""

from __future__ import annotations

import gc
import os
import signal
import sys
import threading

from crosscert.robots.errors import CrosscertError
from crosscert.robots.registry import robot_key

from .checks import check_command
from .parser import UsageError, build_parser, robot_of
from .planning import certify, plan
from .robots import robots
from .setup import checked_entry
from .simulation import simulate, sweep
from .study import study
from .track import check, monitor

__all__ = ["build_parser", "main"]

#: Exit code of an interrupted command (128 + SIGINT, the shell's convention).
EXIT_INTERRUPTED = 130
#: Exit code when the standard output was closed by its reader (128 + SIGPIPE, what ``cat`` gets).
EXIT_BROKEN_PIPE = 141

_COMMANDS = {"check": check, "monitor": monitor, "simulate": simulate, "sweep": sweep, "plan": plan,
             "certify": certify, "study": study, "robots": robots}


#: Seconds after which an interrupt is sent again while the command has not ended (see :class:`_Interrupts`).
_RESEND_S = 1.0


class _Interrupts:
    """SIGINT raises KeyboardInterrupt, as by default, and is remembered.

    C code may swallow it: a C extension (CasADi's SWIG wrappers) may turn the
    KeyboardInterrupt raised inside one of its calls into another exception,
    and one raised inside a ctypes callback (numba's cache notifications, while
    kernels compile) is only printed as "Exception ignored".  So, until the
    command has ended or reported the interrupt, it is sent again every
    ``_RESEND_S`` seconds (longer than the clean-up it interrupts), and
    once interrupted, unraisable exceptions print nothing (a swallowed
    KeyboardInterrupt, or C objects the interrupt left half-built).
    """

    def __init__(self) -> None:
        self.seen = False
        self.reported = False
        self.previous = None
        self._hook = None
        self._done = threading.Event()

    def _handler(self, signum, frame):
        self.seen = True
        if not self._done.is_set():
            timer = threading.Timer(_RESEND_S, self._resend)
            timer.daemon = True
            timer.start()
        raise KeyboardInterrupt

    def _resend(self) -> None:
        if not self._done.is_set():
            os.kill(os.getpid(), signal.SIGINT)

    def _unraisable(self, unraisable) -> None:
        # once interrupted, nothing unraisable is news: a swallowed interrupt is sent again, and what the
        # interrupt stopped half-built in C is finalised with errors (llvmlite's ObjectRef.__del__ on an
        # object whose constructor it cut short, while kernels compile)
        if not self.seen:
            self._hook(unraisable)

    def report(self) -> int:
        """Say "interrupted" once on stderr; the exit code.  The interrupt has been handled: it is not sent again."""
        self._done.set()
        if not self.reported:
            self.reported = True
            print("crosscert: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED

    def finish(self) -> None:
        """The command has ended: no interrupt is sent again."""
        self._done.set()

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGINT, self._handler)
            self._hook, sys.unraisablehook = sys.unraisablehook, self._unraisable
        return self

    def __exit__(self, *exc) -> None:
        self._done.set()
        if self.seen:
            gc.collect()  # the interrupt's debris in reference cycles, finalised while the hook is ours
        if self.previous is not None:
            signal.signal(signal.SIGINT, self.previous)
            sys.unraisablehook = self._hook


#: The interrupts of the command running in this process (None outside :func:`main`).
_INTERRUPTS: _Interrupts | None = None


def main(argv=None) -> int:
    """Entry point of the ``crosscert`` script; returns the exit code.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name (default: ``sys.argv[1:]``).
    """
    global _INTERRUPTS
    with _Interrupts() as interrupts:
        _INTERRUPTS = interrupts
        try:
            try:
                return _main(argv)
            finally:
                interrupts.finish()
        except KeyboardInterrupt:  # one sent again just as the command ended
            return interrupts.report()
        except Exception:
            if not interrupts.seen:
                raise
            return interrupts.report()  # an interrupt a C extension disguised
        finally:
            _INTERRUPTS = None


def _main(argv) -> int:
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        a = build_parser(robot_of(argv)).parse_args(argv)
        a.argv = argv
        a.robot = robot_key(a.robot)  # a robot file by its absolute path: every later lookup finds the same one
        check_command(a, checked_entry(a.robot))  # every option, before any work
        return _COMMANDS[a.command](a)
    except UsageError as exc:
        print(str(exc), file=sys.stderr)
        return 2
    except CrosscertError as exc:
        print(f"crosscert: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if _INTERRUPTS is not None:
            return _INTERRUPTS.report()
        print("crosscert: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except OSError as exc:
        print(f"crosscert: error: {exc}", file=sys.stderr)
        return 2


def _silence_stdout() -> None:
    """After the reader of stdout went away: send what is still buffered to /dev/null, so that the
    interpreter's last flush does not fail again (and print a traceback) on the closed pipe."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (a test's capture)
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
    finally:
        os.close(devnull)
