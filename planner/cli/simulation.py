"""``crosscert simulate`` and ``crosscert sweep``: simulated runs of the benchmark crossing."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crosscert.robots import KinematicModel
from crosscert.robots.registry import get_entry
from crosscert.verifier.plots import plot_run
from crosscert.verifier.settings import VelocityModel, Verdict
from crosscert.verifier.trajfile import write_trajectory

from ..simulate import simulate_bounce, simulate_crossing, simulate_motion
from ..sweep import sweep as run_sweep
from .setup import benchmark_setup, compile_note, progress_bar, simulation_cruise, true_geometry

__all__ = ["simulate", "sweep"]


def simulate(a) -> int:
    """``crosscert simulate``: write the readings of a simulated benchmark crossing or bounce (or, for a robot
    that ships a reference motion instead, of that motion at ``--v-sing``)."""
    entry = get_entry(a.robot)
    robot = entry.robot
    if entry.benchmark is None and entry.motion is not None:
        kin = KinematicModel(robot)
        m = entry.reference_motion()
        run = simulate_motion(kin, m.start, m.goal, a.v_sing, xi_true=true_geometry(robot, a.seed), t_rest=a.t_rest,
                              a_peak=a.a_peak, working_guess=m.q_start, seed=a.seed)
        write_trajectory(a.output, run.t, run.q_meas)
        print(f"wrote {a.output}: {run.n_samples} samples of the reference motion at {run.v_sing} (pose units)/s")
        return 0
    entry, kin, bench = benchmark_setup(a.robot)
    fn = simulate_bounce if a.bounce else simulate_crossing
    run = fn(kin, bench.point, bench.direction, a.v_sing, xi_true=true_geometry(robot, a.seed), t_rest=a.t_rest,
             a_peak=a.a_peak, cruise=simulation_cruise(a), working_guess=bench.q_point, seed=a.seed)
    write_trajectory(a.output, run.t, run.q_meas)
    kind = "bounce" if a.bounce else "crossing"
    start = float(np.dot(run.x_sing - run.x[0], run.direction))  # along the path, to where it meets the true locus
    print(f"wrote {a.output}: {run.n_samples} samples of a {kind} at {run.v_sing} m/s (singular sample {run.k_sing}; "
          f"start {start * 1e3:.1f} mm before the locus)")
    return 0


def sweep(a) -> int:
    """``crosscert sweep``: the paper's Table II on simulated benchmark crossings, with figures."""
    entry, kin, bench = benchmark_setup(a.robot)
    robot = entry.robot
    speeds = a.speeds_list  # parsed and checked by planner.cli.checks
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    models = (VelocityModel.PAPER, VelocityModel.SOUND)
    compile_note(*models)
    bar, cb = progress_bar(None, not a.no_progress, "sweep")
    try:
        rows, figs = run_sweep(robot, kin, bench, speeds, models, xi_true=true_geometry(robot, a.seed), seed=a.seed,
                           progress=cb, record_speed=speeds[0])
    finally:
        if bar is not None:
            bar.close()
    print(f"{'v_sing (m/s)':>12} {'model':>8} {'m_x (mm)':>10} {'m_xd (m/s)':>11} {'detected':>9} {'verdict':>15} {'contained':>9}")
    for r in rows:
        det = "yes" if r.verdict is Verdict.MODE_CHANGED else "no"
        print(f"{r.v_sing:12.3f} {r.velocity_model:>8} {1e3 * r.max_width_pose:10.2f} {r.max_width_velocity:11.3f} "
              f"{det:>9} {r.verdict.value:>15} {str(r.contained):>9}")
    for vm in models:
        lowest = [r.v_sing for r in rows if r.velocity_model == str(vm) and r.verdict is Verdict.MODE_CHANGED]
        print(f"lowest certified v_sing ({vm}): {min(lowest):.3f} m/s" if lowest else f"lowest certified v_sing ({vm}): none")
    for name, (run, boxes) in figs.items():
        png = out / f"sweep_{name}_{run.v_sing:.3f}.png"
        plot_run(png, run.t_s, boxes, run.x_true, run.xd_true, run.k_sing, title=f"{robot.name} crossing at {run.v_sing} m/s, {name} model")
        print(f"wrote {png}")
    return 0
