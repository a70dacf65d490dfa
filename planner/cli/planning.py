"""``crosscert plan`` and ``crosscert certify``: crossings before execution."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from crosscert.verifier.files import atomic_write
from crosscert.verifier.plots import plot_certificate, plot_run
from crosscert.verifier.trajfile import write_trajectory

from ..assumption_cost import ComparisonOutcome, certify_at_robot_a_max, compares
from ..certify.crossing import certify_crossing
from ..execution_proof import describe as describe_execution
from ..worker import SubprocessExecutor
from ..plan import plan_crossing
from ..task import Method, PlanningBounds
from .setup import compile_ahead, phase_bar, task_setup

__all__ = ["plan", "certify"]


def plan(a) -> int:
    """``crosscert plan``: write the planned crossing at ``--v-sing`` as a trajectory file."""
    entry, kin, task = task_setup(a)
    dyn = entry.require_dynamics() if a.method == Method.DYNAMIC else None
    p = plan_crossing(kin, task, a.v_sing, PlanningBounds(a_peak=a.a_peak, method=a.method, dynamics=dyn))
    write_trajectory(a.output, p.t, p.q, x=p.x)
    print(f"wrote {a.output}: {len(p.t)} samples, crossing at sample {p.k_sing} at {p.v_sing} m/s, "
          f"peak |xdd| {np.abs(p.xdd).max():.1f} m/s^2")
    return 0


def certify(a) -> int:
    """``crosscert certify``: v_min, its certificate, the refutation bound; a table, a JSON report and a figure."""
    compile_ahead()  # while this process plans (IPOPT) and compiles the tapes and the pose enumeration
    entry, kin, task = task_setup(a)
    robot = entry.robot
    a_max = None if a.a_max is None else (a.a_max[0] if len(a.a_max) == 1 else a.a_max)
    bounds = PlanningBounds(eps_q=a.eps_q, tracking_error=a.tracking_error, a_max=a_max, a_peak=a.a_peak,
                            method=a.method, dynamics=entry.require_dynamics() if a.method == Method.DYNAMIC else None,
                            execution=a.execution, one_motion=a.one_motion)
    out = Path(a.out)
    units = {u.value for u in robot.joint_units}
    joint_unit = units.pop() if len(units) == 1 else "rad or m (per joint)"
    bar = phase_bar(not a.no_progress, "certify")
    # one worker process for both certifications' counterexample searches: the second reuses the
    # first's imports and NLP solvers (planner.refute builds one per sample count)
    pool = None if a.no_refute else SubprocessExecutor()
    drawing = None
    try:
        cert = certify_crossing(robot, task, bounds, v_low=a.v_low, v_high=a.v_high, tol=a.tol,
                                refute_tol=a.refute_tol, monte_carlo_runs=a.monte_carlo, refute=not a.no_refute, seed=a.seed,
                                progress=bar, kin=kin, executor=pool)
        figure = _figure(cert, bounds, out, joint_unit)
        if figure is not None and pool is not None and compares(robot, cert):
            # the figure depends on the first certificate only: the worker draws it while this process
            # runs the second certification's speed search (the worker is mostly idle then)
            out.mkdir(parents=True, exist_ok=True)
            fn, *args, kwargs = figure[1]
            drawing = pool.submit(fn, Path(args[0]).absolute(), *args[1:], **kwargs)
        # what the assumption buys: the same search under the robot's physical a_max
        cert = certify_at_robot_a_max(robot, task, cert, v_low=a.v_low, v_high=a.v_high, tol=a.tol,
                                      refute_tol=a.refute_tol, refute=not a.no_refute, seed=a.seed, progress=bar, kin=kin, executor=pool)
        files = [] if figure is None else [figure[0]]
        if drawing is not None:
            try:
                drawing.result()
            except Exception:  # e.g. an argument the worker could not receive: drawn here below
                drawing = None
    finally:
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
        if bar is not None:
            bar.close()
    report = cert.summary()
    report["command_line"] = ["crosscert", *a.argv]
    out.mkdir(parents=True, exist_ok=True)
    if figure is not None and drawing is None:
        fn, *args, kwargs = figure[1]
        fn(*args, **kwargs)
    js = out / "certificate.json"
    atomic_write(js, lambda fh: fh.write(json.dumps(report, indent=1)), what="--out")
    files.append(js)
    if a.json:
        print(json.dumps(report))
        return 0
    # widths are the forward tracker's boxes (the paper's Table II); the verdict includes the window passes
    print(f"{'v_sing (m/s)':>12} {'m_x (mm)':>10} {'m_xd (m/s)':>11} {'forward':>15} {'verdict':>15}")
    for r in cert.trials:
        print(f"{r.v_sing:12.4f} {1e3 * r.max_width_pose:10.2f} {r.max_width_velocity:11.3f} "
              f"{r.forward_verdict.value:>15} {r.verdict.value:>15}")
    vmin = "none (no tried speed certifies)" if cert.v_min is None else f"{cert.v_min:.4f} m/s"
    ref = "not computed" if a.no_refute else ("none found" if cert.refutation_bound is None else f"{cert.refutation_bound:.4f} m/s")
    print(f"minimal certified v_sing: {vmin}")
    if cert.v_min_at_lower_end:
        print(f"note: v_min is the slowest speed tried; lower --v-low (now {a.v_low} m/s) to look for a smaller one")
    if cert.certified_below_v_min:
        print(f"note: certification is not monotone here; also certified below v_min at "
              f"{', '.join(f'{v:.4f}' for v in cert.certified_below_v_min)} m/s")
    print(f"refutation bound (no sound tracker certifies at or below): {ref}")
    if cert.v_min is not None and cert.refutation_bound:
        # the JSON's gap_mps is the difference; the ratio is printed beside it, named as such
        print(f"gap (mode-changed): v_min - refutation bound = {cert.v_min - cert.refutation_bound:.4f} m/s "
              f"(gap_mps); ratio v_min / refutation bound = {cert.v_min / cert.refutation_bound:.3f}")
    g = cert.bounce
    if g is not None:
        cf = "none (not at 30 mm)" if g.certified_from is None else f"{1e3 * g.certified_from:.1f} mm"
        fl = "none found" if g.floor is None else f"{1e3 * g.floor:.2f} mm"
        print(f"bounces at {g.speed:.4f} m/s turning back short of the locus: mode-unchanged certified from {cf}; "
              f"crossing floor (no sound tracker certifies at or closer): {fl}")
    mc = cert.monte_carlo
    if mc is not None:
        print(f"Monte Carlo at v_min: {mc.detected_in_class}/{mc.in_class} admissible executions detected "
              f"({mc.detected}/{mc.runs} in all), {len(mc.containment_failures)} containment failures, "
              f"{len(mc.wrong_verdicts)} wrong verdicts")
    phases = ", ".join(f"{k} {v:.1f}" for k, v in cert.timings_s.items())
    if cert.execution is not None:
        print(describe_execution(cert.execution, joint_unit))
    print("a_max used: " + ("none (no certificate)" if cert.a_max_used is None else cert.a_max_used.describe()))
    om = cert.bounds.one_motion
    print(f"reasoning: {cert.bounds.reasoning.value}; one-motion step in the windows: "
          + (f"{om} samples" if om else "off"))
    _print_at_robot_a_max(cert, a.no_refute)
    extra = cert.at_robot_a_max
    more = f" + {extra.elapsed_s:.1f} s at the robot's a_max" if extra.outcome is ComparisonOutcome.COMPUTED else ""
    print(f"elapsed {cert.elapsed_s:.1f} s ({phases}){more}")
    for f in files:
        print(f"wrote {f}")
    return 0


def _print_at_robot_a_max(cert, no_refute: bool) -> None:
    """The v_min and refutation bound under the robot's physical a_max, or why they are not given."""
    at = cert.at_robot_a_max
    robot_bound = ", ".join(f"{x.value:g} {x.unit}" for x in at.a_max.axes)
    if at.outcome is ComparisonOutcome.COINCIDES:
        print(f"at the robot's a_max ({robot_bound}): the same bounds, the same certificate")
        return
    if at.outcome is ComparisonOutcome.NO_CERTIFICATE:
        print(f"at the robot's a_max ({robot_bound}): not computed (no certificate to compare with)")
        return
    vmin = "none (no tried speed certifies)" if at.v_min is None else f"{at.v_min:.4f} m/s"
    if at.v_min is not None and at.v_min_at_lower_end:
        vmin += f" (the slowest speed tried, {at.v_low:.4f} m/s)"
    ref = "not computed" if no_refute else ("none found" if at.refutation_bound is None
                                            else f"{at.refutation_bound:.4f} m/s")
    print(f"at the robot's a_max ({robot_bound}): minimal certified v_sing {vmin}; refutation bound {ref}")


def _figure(cert, bounds, out: Path, joint_unit: str):
    """``(png path, (function, *args, kwargs))`` of the certificate's figure; None without a certificate.

    The call is a module-level function with picklable arguments, so the worker process can draw it.
    """
    if cert.enclosures is None:
        return None
    e, p = cert.enclosures, cert.trajectory
    name = cert.robot_name
    png = out / f"certificate_{name}_{cert.v_min:.3f}.png"
    forward = {"x_lo": e.x_lo, "x_hi": e.x_hi, "xd_lo": e.xd_lo, "xd_hi": e.xd_hi, "mode": e.mode}
    text = (f"{bounds.method} plan, eps_q = {cert.bounds.eps_q:.3g} {joint_unit}, a_max = "
            f"({', '.join(f'{x.value:.4g} {x.unit}' for x in cert.a_max_used.axes)}), "
            f"t_s = {cert.bounds.t_s:.3g} s, "
            f"{cert.execution.kind.value} executions")
    if cert.window is not None:  # the window passes certified: draw them, the forward pass only beside them
        call = (plot_certificate, png, p.t_s, forward, cert.window, p.x, p.xd, p.k_sing,
                {"title": f"{name}: crossing at v_min = {cert.v_min:.3f} m/s certified by window reasoning",
                 "bounds": text})
    else:
        call = (plot_run, png, p.t_s, forward, p.x, p.xd, p.k_sing,
                {"title": f"{name}: crossing at v_min = {cert.v_min:.3f} m/s certified by the forward pass",
                 "truth": "planned", "bounds": text})
    return png, call
