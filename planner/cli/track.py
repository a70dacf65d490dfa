"""``crosscert check`` and ``crosscert monitor``: the tracker on a recording, after or during execution."""

from __future__ import annotations

import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

from robots.errors import CrosscertError, TrajectoryFileError
from verifier.plots import plot_run
from verifier.step import Backend, Tracker
from verifier.tracker import Verdict, initial_box_from_mode, track, verdict_of
from verifier.trajfile import TrajectoryReader, read_trajectory

from .setup import progress_bar, tracker_setup

__all__ = ["check", "monitor", "Monitor"]

#: What ``check`` and ``monitor`` print on stderr for an inconsistent run.
INCONSISTENT_HINT = ("a box became empty at step {k}: a_max, the calibration box, eps_q or the initial box is "
                     "violated by the data")


def check(a) -> int:
    """``crosscert check``: track a recording file and print the verdict; returns the exit code."""
    robot, model, make_settings, x0 = tracker_setup(a)
    traj = read_trajectory(a.trajectory, robot.n)
    settings = make_settings(traj.t_s)
    bar, cb = progress_bar(len(traj.t), not a.no_progress and not a.json, "tracking")
    try:
        res = track(model, traj.q, settings, x0=x0, initial_mode=a.initial_mode, progress=cb, backend=a.backend)
    finally:
        if bar is not None:
            bar.close()
    if a.plot:
        plot_run(a.plot, traj.t_s, {"x_lo": res.x_lo, "x_hi": res.x_hi, "xd_lo": res.xd_lo, "xd_hi": res.xd_hi, "mode": res.mode},
                 title=f"{Path(a.trajectory).name}: {res.verdict.value}")
    out = res.summary()
    out["velocity_model"] = str(settings.velocity_model)
    if a.json:
        print(json.dumps(out))
    else:
        print(f"verdict: {out['verdict']}")
        for key in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step", "steps"):
            print(f"{key}: {out[key]}")
        print(f"max width pose (m_x): {1e3 * out['max_width_pose_m']:.3f} mm")
        print(f"max width velocity (m_xd): {out['max_width_velocity_mps']:.4g} m/s")
        print(f"elapsed: {out['elapsed_s']:.2f} s")
        if res.verdict is Verdict.INCONSISTENT:
            print(INCONSISTENT_HINT.format(k=res.inconsistent_at_step), file=sys.stderr)
    return 3 if res.verdict is Verdict.INCONSISTENT else 0


class Monitor:
    """What ``crosscert monitor`` has decided so far.

    Samples wait in ``pending`` until the sampling period is known (at the
    second sample, or the first with ``--t-s``); then the compiled
    :class:`~verifier.step.Tracker` starts from ``--x0`` or from the first
    sample's box of ``--initial-mode``, and every later sample is tracked as
    soon as it is fed.

    Parameters
    ----------
    a : argparse.Namespace
    model : verifier.model.IntervalModel
    make_settings : callable
        ``t_s -> TrackerSettings``.
    x0 : (lo, hi) or None
        The ``--x0`` box.
    """

    def __init__(self, a, model, make_settings, x0):
        self.a, self.model, self.make_settings, self.x0 = a, model, make_settings, x0
        self.tracker = None
        self.pending = []  # (line, t, q) read before the tracker could start
        self.samples = 0
        self.latency_ns = []

    def feed(self, line: int, t: float, q, t_s: float | None) -> None:
        """Track the sample read on ``line`` (time ``t`` s, readings ``q`` rad) and print its events."""
        self.samples += 1
        self.pending.append((line, float(t), q))
        if self.tracker is None:
            if t_s is None:
                return
            settings = self.make_settings(t_s)
            x0 = self.x0
            if x0 is None:
                x0 = initial_box_from_mode(self.model, self.pending[0][2], self.a.initial_mode, settings,
                                           backend=self.a.backend)
            self.tracker = Tracker(self.model, settings, x0, backend=self.a.backend,
                                   spread_hypotheses=self.a.spread_hypotheses)
        for line, t, q in self.pending:
            t0 = time.perf_counter_ns()
            r = self.tracker.update(q)
            self.latency_ns.append(time.perf_counter_ns() - t0)
            for e in r.events:
                ev = {"event": e.value, "k": r.k, "t": t, "line": line, "mode": r.mode}
                text = f"sample {r.k} (t = {t:.9g} s): {e}" + (f", mode {r.mode:+d}" if r.mode else "")
                print(json.dumps(ev) if self.a.json else text, flush=True)
        self.pending.clear()

    def summary(self, error: str | None = None) -> dict:
        """The verdict so far (rules of :func:`verifier.tracker.verdict_of`), counts and latencies (us)."""
        st = None if self.tracker is None else self.tracker.state
        bad = -1 if st is None else int(st.bad_at[0])
        init = 0 if st is None else int(st.init_mode[0])
        final = int(st.mode[0]) if st is not None and bad < 0 else 0
        lat = np.array(self.latency_ns, dtype=float) / 1e3
        stat = (lambda f: round(float(f(lat)), 1) if lat.size else None)  # noqa: E731
        return {
            "verdict": verdict_of(init, final, bad >= 0).value,
            "initial_mode": init,
            "final_mode": final,
            "certified_at_step": int(st.streak[0]) if final else None,
            "inconsistent_at_step": bad if bad >= 0 else None,
            "steps": 0 if st is None else st.k,
            "t_s": None if st is None else float(self.tracker.config.settings.t_s),
            "max_width_pose_m": None if st is None else float(st.max_width_pose[0]),
            "max_width_velocity_mps": None if st is None else float(st.max_width_velocity[0]),
            "velocity_model": self.a.velocity_model,
            "latency_us_mean": stat(np.mean),
            "latency_us_p99": stat(lambda v: np.percentile(v, 99)),
            "latency_us_max": stat(np.max),
            "interrupted": error is not None,
            "error": error,
        }

    def finish(self, error: str | None = None) -> int:
        """Print the summary (the last line of output) and return the exit code."""
        out = self.summary(error)
        if self.a.json:
            print(json.dumps(out), flush=True)
        else:
            print(f"verdict: {out['verdict']}" + (" (so far: input interrupted)" if error else ""))
            for key in ("initial_mode", "final_mode", "certified_at_step", "inconsistent_at_step", "steps"):
                print(f"{key}: {out[key]}")
            if out["steps"]:
                print(f"update latency: mean {out['latency_us_mean']} us, p99 {out['latency_us_p99']} us, "
                      f"max {out['latency_us_max']} us")
            sys.stdout.flush()
        if out["inconsistent_at_step"] is not None and error is None:  # else the error is the one line on stderr
            print(INCONSISTENT_HINT.format(k=out["inconsistent_at_step"]), file=sys.stderr)
        return 3 if out["verdict"] == Verdict.INCONSISTENT.value else 0


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
    robot, model, make_settings, x0 = tracker_setup(a)
    settings = make_settings(robot.t_s if a.t_s is None else a.t_s)
    settings.validated(robot.n)  # bad bounds fail before any input is read
    if a.backend == Backend.COMPILED.value:
        load_kernels(robot, model, settings, a.spread_hypotheses)
    mon = Monitor(a, model, make_settings, x0)
    stdin = a.trajectory == "-"
    with contextlib.nullcontext(sys.stdin) if stdin else open(a.trajectory, newline="") as src:
        reader = TrajectoryReader(src, robot.n, "<stdin>" if stdin else a.trajectory, t_s=a.t_s)
        try:
            for line, values in reader:
                t, q = reader.columns(values)[:2]
                mon.feed(line, t, q, reader.t_s)
            if mon.samples < 2:
                raise TrajectoryFileError(f"{reader.name}: at least two samples are needed, got {mon.samples}")
        except (CrosscertError, OSError, KeyboardInterrupt) as exc:
            mon.finish(error=str(exc) or type(exc).__name__)
            raise
    return mon.finish()
