"""``crosscert check`` and ``crosscert monitor``: the tracker on a recording, after or during execution."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from crosscert.robots.errors import CrosscertError, InputError, TrajectoryFileError
from crosscert.verifier.clock import SampleClock
from crosscert.verifier.plots import plot_run
from crosscert.verifier.step import Backend
from crosscert.verifier.tracker import Tracker
from crosscert.verifier.settings import Verdict
from crosscert.verifier.tracker import initial_box_from_mode
from crosscert.verifier.recordings import open_recording
from crosscert.verifier.window import HypothesisStatus, OnlineMonitor, Reasoning, VerdictReason, track_window

from ..certify.envelope import CertifiedEnvelope, EnvelopeMonitor, EnvelopeState
from ..progress import Phase, enter
from ..refute import RefutingExplainer
from .checks import joint_names
from .setup import compile_ahead, phase_bar, tracker_setup

__all__ = ["check", "monitor", "Monitor"]

#: What ``check`` and ``monitor`` print on stderr for an inconsistent run.
INCONSISTENT_HINT = ("a box became empty at step {k}: a_max, the calibration box, eps_q, the initial speed bound "
                     "(--xd0: a recording that starts while the robot moves needs it) or the initial box is "
                     "violated by the data")


#: Exit code of ``check --plot`` when the figure could not be written (the verdict is printed before):
#: a file asked for is missing, as for any bad output path.
EXIT_NO_FIGURE = 2

#: Longest recording (samples) ``check`` keeps in memory for window reasoning (16 MB of readings for
#: n = 6; the tubes of the passes take about 16 geometries x 2 hypotheses x 64 bytes per sample more).
WINDOW_MAX_SAMPLES = 200_000

#: Relative width of a latency histogram bin, and the number of bins (1 ns to ~ 4 h).
_LATENCY_BIN_RATIO = 0.01
_LOG_BIN_RATIO = float(np.log1p(_LATENCY_BIN_RATIO))
_LATENCY_BINS = 3000
#: Envelope states in which the certificate answers and the tracker may wait (``monitor --certificate``).
_HELD = (EnvelopeState.INSIDE, EnvelopeState.CERTIFIED)

#: Keys of the monitor's summary that say nothing about a file read at once.
_MONITOR_ONLY = ("latency_us_mean", "latency_us_p99", "latency_us_max", "interrupted", "error", "verdict_so_far")


def _print_warnings(reader) -> None:
    for w in reader.warnings[getattr(reader, "_printed", 0):]:
        print(f"crosscert: warning: {w}", file=sys.stderr)
    reader._printed = len(reader.warnings)


def _recording(a, robot):
    """The recording ``a.trajectory`` names, opened (a CSV, a ROS 2 bag or an ``.npz``): one reader whose
    ``samples()`` are ``(position, t, q)``, every format's times checked alike."""
    return open_recording(a.trajectory, robot.n, topic=a.topic, stamp=a.stamp,
                          joints=None if a.joints is None else joint_names(a.joints, robot.n),
                          t_s=a.t_s, nominal_t_s=robot.t_s, q_range=(robot.q_lo_array, robot.q_hi_array),
                          stamp_error=a.stamp_error)


def _tracked(a, robot, model, run, bar):
    """The recording through ``run`` (the forward pass), then the window passes when they may decide:
    ``(summary, file name)``; ``bar`` (a :class:`PhaseBar` or None) is told each phase."""
    readings = [] if a.reasoning == Reasoning.WINDOW.value else None
    stamps = []
    enter(bar, Phase.FORWARD, unit="sample")
    with _recording(a, robot) as reader:
        name = reader.name
        for line, t, q in reader.samples():
            _print_warnings(reader)
            run.feed(line, t, q, reader.t_s)
            if readings is not None:
                readings.append(q)
                stamps.append(t)
                if len(readings) > WINDOW_MAX_SAMPLES:
                    readings = None  # too long for the window: the forward verdict stands
            if bar is not None:
                bar(1)
    if run.samples < 2:
        raise TrajectoryFileError(f"{name}: at least two samples are needed, got {run.samples}")
    run.settle()
    out = {k: v for k, v in run.summary().items() if k not in _MONITOR_ONLY}
    run.close()
    # the tracker with its anchored windows (what monitor says), before any window over the whole recording
    out["online_verdict"] = out["verdict"]
    out["window"] = None
    if a.reasoning == Reasoning.WINDOW.value and out["verdict"] == Verdict.UNKNOWN.value:
        if readings is None:
            print(f"crosscert: note: window reasoning skipped: the recording is longer than {WINDOW_MAX_SAMPLES} "
                  "samples; the verdict is the forward tracker's", file=sys.stderr)
        else:
            enter(bar, Phase.WINDOW, unit="")
            # stops the window early on a recording no sound method can decide (both final modes explained)
            explainer = RefutingExplainer()
            # the run's own settings: a tracker re-seeded by a window starts with no bound on its velocity
            # the samples' times as the tracker read them (steps of t_s: the constant-period window)
            clock = SampleClock.from_stamps(stamps, run.t_s, a.stamp_error, name=name)
            win = track_window(model, np.asarray(readings, dtype=float), run.online.settings,
                               x0=run.x0_used, backend=a.backend, explainer=explainer, clock=clock)
            out["window"] = win.summary()
            out["window"]["explainer"] = [
                {"final_mode": e.final_mode, "search": None if e.kind is None else e.kind.value,
                 "outcome": e.outcome.value, "ipopt_s": e.solve_s, "wall_s": e.wall_s} for e in explainer.log]
            out["verdict"] = win.verdict.value
            if win.verdict in (Verdict.MODE_CHANGED, Verdict.MODE_UNCHANGED):
                out["final_mode"] = (out["initial_mode"] if win.verdict is Verdict.MODE_UNCHANGED
                                     else -out["initial_mode"])
                # the surviving hypothesis' tube at the last sample: inside that mode's poses of the last reading
                h = next(h for h in win.hypotheses if h.status is not HypothesisStatus.REFUTED)
                out["final_pose_lo"], out["final_pose_hi"] = h.x_lo[-1].tolist(), h.x_hi[-1].tolist()
    return out, name


def check(a) -> int:
    """``crosscert check``: track a recording while it is read and print the verdict; returns the exit code.

    Memory does not grow with the recording's length, except with ``--plot``
    (the boxes of every sample are kept for the figure) and with ``window``
    reasoning, which keeps the readings of recordings up to
    :data:`WINDOW_MAX_SAMPLES` samples for the window passes (run when the
    forward tracker leaves the verdict open).
    """
    if a.backend == Backend.COMPILED.value:
        compile_ahead(a.velocity_model)
    robot, model, make_settings, x0 = tracker_setup(a)
    envelope = _envelope(a, robot)
    t0 = time.perf_counter()
    run = Monitor(a, model, make_settings, x0, record=a.plot is not None, echo=False, worker=False, envelope=envelope)
    bar = phase_bar(not a.no_progress and not a.json, "check")
    try:
        out, name = _tracked(a, robot, model, run, bar)
    finally:
        if bar is not None:
            bar.close()
    out["elapsed_s"] = time.perf_counter() - t0
    if a.json:
        print(json.dumps(out))
    else:
        print(f"verdict: {out['verdict']}")
        if out["certificate"] is not None:
            print(out["certificate"]["describe"])
        if out["window"] is not None:
            w = out["window"]
            hyps = ", ".join("final mode {:+d} {}".format(h["final_mode"], h["status"]) for h in w["hypotheses"])
            print(f"online (the tracker and its anchored windows): {out['online_verdict']}; window passes over "
                  f"the whole run: {w['verdict']} ({hyps})")
            if w["reason"] == VerdictReason.UNDECIDABLE.value:
                print("window reason: undecidable: each final mode is explained by a verified admissible motion, "
                      "so no sound method can decide this recording (stopped early)")
        for key in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step", "steps"):
            print(f"{key}: {_value_text(key, out)}")
        print(f"max width pose (m_x): {1e3 * out['max_width_pose_m']:.3f} mm")
        print(f"max width velocity (m_xd): {out['max_width_velocity_mps']:.4g} m/s")
        print(f"elapsed: {out['elapsed_s']:.2f} s")
    if out["inconsistent_at_step"] is not None:
        print(INCONSISTENT_HINT.format(k=out["inconsistent_at_step"]), file=sys.stderr)
    if a.plot:
        # after the verdict: a figure that cannot be written must not cost it
        sys.stdout.flush()
        try:
            rec = run.recorded()
            plot_run(a.plot, run.t_s, rec, title=f"{Path(name).name}: {out['verdict']}", bounds=run.bounds_text(),
                     t=rec.pop("t"))
        except (CrosscertError, OSError) as exc:
            print(f"crosscert: error: the verdict above stands, but the figure was not written: {exc}",
                  file=sys.stderr)
            return EXIT_NO_FIGURE
    return 3 if out["verdict"] == Verdict.INCONSISTENT.value else 0


class LatencyStats:
    """Mean, maximum and quantiles of update latencies in constant memory (a log-binned histogram).

    Quantiles are the upper edge of their bin: at most :data:`_LATENCY_BIN_RATIO`
    (1 %) above the true value, never below it.
    """

    def __init__(self) -> None:
        self.count, self.total_ns, self.max_ns = 0, 0, 0
        self.bins = np.zeros(_LATENCY_BINS + 1, dtype=np.int64)

    def add(self, ns: int) -> None:
        """Count one latency, ns."""
        self.count += 1
        self.total_ns += ns
        self.max_ns = max(self.max_ns, ns)
        self.bins[min(_LATENCY_BINS, int(math.log(max(ns, 1)) / _LOG_BIN_RATIO))] += 1  # math: a scalar, once per sample

    def mean_us(self) -> float | None:
        """Mean latency, µs (None before the first sample)."""
        return round(self.total_ns / self.count / 1e3, 1) if self.count else None

    def max_us(self) -> float | None:
        """Largest latency, µs (None before the first sample)."""
        return round(self.max_ns / 1e3, 1) if self.count else None

    def quantile_us(self, p: float) -> float | None:
        """The ``p`` quantile, µs (the upper edge of its bin, capped by the maximum)."""
        if not self.count:
            return None
        k = int(np.searchsorted(np.cumsum(self.bins), p * self.count))
        return round(min(np.exp((k + 1) * _LOG_BIN_RATIO), self.max_ns) / 1e3, 1)


class Monitor:
    """What ``crosscert monitor`` (or ``check``, reading a file) has decided so far.

    Samples wait in ``pending`` until the sampling period is known (at the
    second sample, or the first with ``--t-s``); then the
    :class:`~verifier.window.OnlineMonitor` starts from ``--x0`` or from the
    first sample's box of ``--initial-mode``, and every later sample is
    tracked as soon as it is fed.  ``monitor`` runs its anchored window on a
    worker thread; ``check`` runs it inline, at fixed window lengths, so that
    its answers do not depend on the machine's speed.

    Parameters
    ----------
    a : argparse.Namespace
    model : verifier.model.IntervalModel
    make_settings : callable
        ``t_s -> TrackerSettings``.
    x0 : (lo, hi) or None
        The ``--x0`` box.
    record : bool
        Keep the boxes and mode of every sample (for a figure).
    echo : bool
        Print every event as it happens (``monitor``).
    worker : bool
        The anchored window on a thread (``monitor``) or inline (``check``).
    envelope : planner.certify.envelope.EnvelopeMonitor, optional
        ``--certificate``: the certified envelope the readings are checked against first.
    """

    def __init__(self, a, model, make_settings, x0, *, record: bool = False, echo: bool = True, worker: bool = True,
                 envelope=None):
        self.a, self.model, self.make_settings, self.x0 = a, model, make_settings, x0
        self.envelope = envelope  # --certificate: planner.certify.envelope.EnvelopeMonitor
        self._env_clock = None  # --certificate: the stamps, which must come every t_s
        self.record, self.echo, self.worker = record, echo, worker
        self.online = None  # the verifier's OnlineMonitor, once the sampling period is known
        self.x0_used = None  # the initial box the tracker started from
        self.t_s = None
        self.pending = []  # (line, t, q) read before the tracker could start
        self.samples = 0
        self.times = {}  # sample -> (t, line) of the samples a window's event may still be about
        self.latency = LatencyStats()
        self.envelope_latency = LatencyStats()
        self.catch_up_latency = LatencyStats()  # --certificate: the held samples, tracked once the envelope is left
        self.backlog = []  # --certificate: (line, t, q) held while the certificate answers
        self.boxes = {"x_lo": [], "x_hi": [], "xd_lo": [], "xd_hi": [], "mode": [], "t": []}

    def _start(self, t_s: float) -> None:
        settings = self.make_settings(t_s)
        self.t_s = float(t_s)
        if self.envelope is not None and abs(self.t_s - self.envelope.envelope.t_s) > 1e-9 * self.t_s:
            raise InputError(f"--certificate: the recording's step is {self.t_s:g} s, the certified plan's "
                             f"{self.envelope.envelope.t_s:g} s: the certificate covers executions sampled "
                             "at its plan's period")
        x0 = self.x0
        if x0 is None:
            x0 = initial_box_from_mode(self.model, self.pending[0][2], self.a.initial_mode, settings,
                                       backend=self.a.backend)
        self.x0_used = x0
        self.online = OnlineMonitor(self.model, settings, x0, backend=self.a.backend, horizon=self.a.horizon,
                                    worker=self.worker, window=self.a.reasoning == Reasoning.WINDOW.value,
                                    spread_hypotheses=getattr(self.a, "spread_hypotheses", False),
                                    clock=SampleClock(self.t_s, self.a.stamp_error))

    def feed(self, line: int, t: float, q, t_s: float | None) -> None:
        """Track the sample read on ``line`` (time ``t`` s, readings ``q`` rad) and print its events."""
        self.samples += 1
        self.pending.append((line, float(t), q))
        if self.online is None:
            if t_s is None:
                return
            self._start(t_s)
        for line, t, q in self.pending:
            if self.envelope is not None:
                self._feed_envelope(line, t, q)
                if self.envelope.status.state in _HELD:
                    # inside the certified envelope the certificate answers: the tracker catches up later
                    self.backlog.append((line, t, q))
                    continue
                self.catch_up()
            self._track(line, t, q, self.latency)
        self.pending.clear()

    def _track(self, line: int, t: float, q, latency) -> None:
        """One sample through the online monitor: its latency, its boxes when recorded, its events."""
        t0 = time.perf_counter_ns()
        r = self.online.update(q, t)
        latency.add(time.perf_counter_ns() - t0)
        self.times[r.k] = (t, line)
        if self.record:
            for key, v in zip(self.boxes, (*r.x, *r.xd, r.mode, t)):
                self.boxes[key].append(v)
        self._events(r.events)
        # a window's event is about a sample at most a horizon back
        self.times.pop(r.k - self.online.horizon - 2, None)

    def _events(self, events) -> None:
        for e in events:
            if self.record and e.by_window:
                self._redraw(e)
            if not self.echo:
                continue
            t, line = self.times.get(e.k, (math.nan, None))
            ev = {"event": e.event.value, "k": e.k, "t": t, "line": line, "mode": e.mode}
            text = f"sample {e.k} (t = {t:.9g} s): {e.event}" + (f", mode {e.mode:+d}" if e.mode else "")
            if e.known_at != e.k:
                ev["known_at_k"] = e.known_at
                text += f" (known at sample {e.known_at}" + (", by window reasoning)" if e.by_window else ")")
            print(json.dumps(ev) if self.a.json else text, flush=True)

    def _redraw(self, e) -> None:
        """A window's decision in the figure: the mode drawn at the sample it is about is the decided one
        (the samples after it are the re-seeded tracker's as they come)."""
        if e.k < len(self.boxes["mode"]):
            self.boxes["mode"][e.k] = e.mode

    def catch_up(self) -> None:
        """``--certificate``: the samples held while the readings were in the envelope, through the tracker now
        (when one leaves it, the plan ends, or the run's summary is asked); timed apart from the live samples."""
        if not self.backlog or self.online is None:
            return
        for line, t, q in self.backlog:
            self._track(line, t, q, self.catch_up_latency)
        self.backlog.clear()

    def _feed_envelope(self, line: int, t: float, q) -> None:
        """``--certificate``: the reading against the certified envelope; an event when the state changes."""
        if self._env_clock is None:
            self._env_clock = SampleClock(self.t_s, name=self.a.trajectory)
        self._env_clock.append(t, where=f"line {line}")
        if not self._env_clock.even:
            raise InputError(f"{self.a.trajectory}, line {line}: a sample was dropped before this one, and "
                             "--certificate pairs each reading with the certified plan's sample of the same index: "
                             "track this recording without --certificate")
        before = self.envelope.status.state
        t0 = time.perf_counter_ns()
        st = self.envelope.update(q)
        self.envelope_latency.add(time.perf_counter_ns() - t0)
        if st.state is before or not self.echo or st.state is EnvelopeState.BEYOND_PLAN:
            return
        ev = {"event": f"certificate-{st.state.value}", "k": st.k, "t": t, "line": line, **st.summary()}
        print(json.dumps(ev) if self.a.json else f"sample {st.k} (t = {t:.9g} s): {self.envelope.describe()}",
              flush=True)

    def settle(self, timeout: float | None = None) -> None:
        """The held samples tracked, and the anchored window's last attempt over every reading (its events
        printed): before a summary of the whole input."""
        self.catch_up()
        if self.online is not None:
            self._events(self.online.settle(timeout))

    def close(self, wait: bool = True) -> None:
        """Stop the window's worker: after its running attempt, or at once for an interrupted run."""
        if self.online is not None:
            self.online.close(None if wait else 0.0)

    def recorded(self) -> dict:
        """The kept boxes as arrays: ``x_lo, x_hi, xd_lo, xd_hi`` (K, n), m and m/s, ``mode`` (K,), and the
        samples' stamps ``t`` (K,), s."""
        return {k: np.array(v) for k, v in self.boxes.items()}

    def bounds_text(self) -> str:
        """The bounds the run assumed, for a figure: eps_q, a_max, t_s and the velocity model."""
        s, units = self.online.settings, self.model.robot.assumptions
        return (f"eps_q = {np.max(s.eps_q):.3g} {units.unit('eps_q')}, a_max = {np.max(s.a_max):.3g} "
                f"{units.unit('a_max')}, t_s = {s.t_s:.3g} s, "
                f"velocity model {s.velocity_model}")

    def summary(self, error: str | None = None) -> dict:
        """The verdict, counts, the final pose box and latencies (us).

        ``verdict_so_far`` is the verdict on the samples read (the certified
        modes at the first and newest sample, :meth:`OnlineMonitor.verdict`);
        ``verdict`` is the same unless the input was interrupted (``error``),
        when it is ``unknown``: a prefix says nothing about the samples that
        never came.  Call :meth:`settle` first for the window's last word.
        """
        mon = self.online
        started = mon is not None and mon.k >= 0
        so_far = Verdict.UNKNOWN.value if not started else mon.verdict().value
        init = mon.initial_mode if started else 0
        final = mon.mode if started else 0
        step = mon.since if started and final else None
        bad = mon.inconsistent_at if started and mon.inconsistent_at >= 0 else None
        certificate = None
        if self.envelope is not None:
            env, status = self.envelope.envelope, self.envelope.status
            certificate = {**status.summary(), "decided_at_sample": env.decided_at, "describe": self.envelope.describe(),
                           "latency_us_mean": self.envelope_latency.mean_us(),
                           "latency_us_max": self.envelope_latency.max_us(),
                           "tracked_later": self.catch_up_latency.count,
                           "tracked_later_ms": round(self.catch_up_latency.total_ns / 1e6, 1)}
            if status.state is EnvelopeState.CERTIFIED and so_far != Verdict.INCONSISTENT.value:
                # the readings held to the certified run through its decision and up to now: its verdict is this
                # run's; a decided tracker that disagrees means an assumption was violated
                if so_far != Verdict.UNKNOWN.value and so_far != env.verdict.value:
                    so_far = Verdict.INCONSISTENT.value
                else:
                    so_far, init, final, step = env.verdict.value, env.initial_mode, env.final_mode, env.decided_at
        final_box = started and mon.consistent
        x_final = mon.boxes[0] if final_box else None
        return {
            "certificate": certificate,
            # a verdict is about the whole recording: an interrupted one has only a prefix's
            "verdict": Verdict.UNKNOWN.value if error is not None else so_far,
            "verdict_so_far": so_far,
            "initial_mode": init,
            "final_mode": final,
            "certified_at_step": step,
            "inconsistent_at_step": bad,
            "steps": mon.k + 1 if started else 0,
            "t_s": self.t_s,
            # the pose box at the last sample (in the final mode when it is certified), m
            "final_pose_lo": x_final[0].tolist() if final_box else None,
            "final_pose_hi": x_final[1].tolist() if final_box else None,
            "max_width_pose_m": mon.max_width_pose if started else None,
            "max_width_velocity_mps": mon.max_width_velocity if started else None,
            "velocity_model": self.a.velocity_model,
            "reasoning": self.a.reasoning,
            "window_decisions": 0 if mon is None else mon.decisions,
            "latency_us_mean": self.latency.mean_us(),
            "latency_us_p99": self.latency.quantile_us(0.99),
            "latency_us_max": self.latency.max_us(),
            "interrupted": error is not None,
            "error": error,
        }

    def finish(self, error: str | None = None) -> int:
        """Print the summary (the last line of output) and return the exit code."""
        out = self.summary(error)
        self.close(wait=error is None)
        if self.a.json:
            print(json.dumps(out), flush=True)
        else:
            print(f"verdict: {out['verdict']}" + (f" (input interrupted; on the {out['steps']} samples read: "
                                                   f"{out['verdict_so_far']})" if error else ""))
            for key in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step", "steps"):
                print(f"{key}: {_value_text(key, out)}")
            if out["certificate"] is not None:
                print(out["certificate"]["describe"])
            if out["steps"]:
                print(f"update latency: mean {out['latency_us_mean']} us, p99 {out['latency_us_p99']} us, "
                      f"max {out['latency_us_max']} us")
            sys.stdout.flush()
        if out["inconsistent_at_step"] is not None and error is None:  # else the error is the one line on stderr
            print(INCONSISTENT_HINT.format(k=out["inconsistent_at_step"]), file=sys.stderr)
        return 3 if out["verdict"] == Verdict.INCONSISTENT.value else 0


def _value_text(key: str, out: dict) -> str:
    """A summary value in words where JSON has null: the step of a verdict no single sample decided."""
    v = out[key]
    if v is not None:
        return str(v)
    if key == "certified_at_step":
        decided = out["verdict"] in (Verdict.MODE_CHANGED.value, Verdict.MODE_UNCHANGED.value)
        if decided and out.get("window") is not None:
            return "none: decided by window reasoning over the whole run"
        return "none: the final mode is not certified"
    return "none"


def _envelope(a, robot):
    """``--certificate``: the envelope check of this run (read and checked before any input), or None."""
    if getattr(a, "certificate", None) is None:
        if getattr(a, "certified_plan", None) is not None:
            raise InputError("--certified-plan goes with --certificate")
        return None
    eps_q = robot.eps_q if a.eps_q is None else a.eps_q
    return EnvelopeMonitor(CertifiedEnvelope.load(a.certificate, robot, eps_q, a.certified_plan))


def load_kernels(robot, model, settings, spread_hypotheses):
    """Load the compiled kernels (about 0.4 s from the on-disk cache) on a throw-away tracker, before the
    first sample is read, so that the latencies measured are those of the tracking alone."""
    box = tuple(np.asarray(v, dtype=np.float64) for v in robot.x_bounds)
    Tracker(model, settings, box, spread_hypotheses=spread_hypotheses).update(np.zeros(robot.n))


def monitor(a) -> int:
    """``crosscert monitor``: track a CSV stream line by line, print events as they happen, then the summary.

    Returns the exit code; on an error (bad line, Ctrl-C) the summary so far is
    printed, marked interrupted, before the error propagates to :func:`main`.
    """
    if a.backend == Backend.COMPILED.value and not a.spread_hypotheses:
        compile_ahead(a.velocity_model)
    robot, model, make_settings, x0 = tracker_setup(a)
    settings = make_settings(robot.t_s if a.t_s is None else a.t_s)
    settings.validated(robot.n)  # bad bounds fail before any input is read
    if a.backend == Backend.COMPILED.value:
        load_kernels(robot, model, settings, a.spread_hypotheses)
    mon = Monitor(a, model, make_settings, x0, envelope=_envelope(a, robot))
    with _recording(a, robot) as reader:
        try:
            for line, t, q in reader.samples():
                _print_warnings(reader)
                mon.feed(line, t, q, reader.t_s)
            if mon.samples < 2:
                raise TrajectoryFileError(f"{reader.name}: at least two samples are needed, got {mon.samples}")
        except BrokenPipeError:
            raise  # the reader of our output is gone: no summary to print, a quiet end (main)
        except (CrosscertError, OSError, KeyboardInterrupt) as exc:
            mon.finish(error=str(exc) or type(exc).__name__)
            raise
        try:
            mon.settle()  # the end of the input: the window's last attempt over every reading
        except KeyboardInterrupt as exc:
            mon.finish(error=str(exc) or type(exc).__name__)
            raise
    return mon.finish()
