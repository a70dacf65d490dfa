"""``crosscert plan`` and ``crosscert certify``: crossings before execution."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from crosscert.robots.registry import get_entry
from crosscert.verifier.files import atomic_write
from crosscert.verifier.settings import Verdict
from crosscert.verifier.plots import plot_certificate, plot_run
from crosscert.verifier.trajfile import write_trajectory
from crosscert.verifier.window import online_boxes

from ..assumption_cost import ComparisonOutcome, certify_at_robot_a_max, compares
from ..certify.crossing import certify_crossing
from ..certify.trajectory import PlanSource, certify_path, certify_trajectory
from ..execution_proof import describe as describe_execution
from ..worker import SubprocessExecutor
from ..plan import plan_crossing
from ..models import interval_model, kinematic_model
from ..progress import suffixed
from ..refute import SearchCompleteness
from ..task import ExecutionKind, Method, PlanningBounds
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
    if a.plan is not None:
        return _certify_given_plan(a)
    entry, kin, task = task_setup(a)
    robot = entry.robot
    bounds = _bounds(a, entry, a.execution or ExecutionKind.CARTESIAN)
    out = Path(a.out)
    joint_unit = _joint_unit(robot)
    bar = phase_bar(not a.no_progress, "certify")
    cert, figure, files, drawing = _certify_twice(a, robot, task, bounds, kin, out, joint_unit, bar)
    report = cert.summary()
    report["command_line"] = ["crosscert", *a.argv]
    out.mkdir(parents=True, exist_ok=True)
    if cert.trajectory is not None:
        # the certified plan beside its certificate: what `monitor --certificate` holds a run against
        files.append(out / CERTIFIED_PLAN)
        report["plan"] = _write_plan(files[-1], cert.trajectory)
    if figure is not None and drawing is None:
        fn, *args, kwargs = figure[1]
        fn(*args, **kwargs)
    if _write_report(out, report, files, a.json):
        return 0
    _print_certify(a, cert, files, joint_unit)
    return 0


def _certify_twice(a, robot, task, bounds: PlanningBounds, kin, out: Path, joint_unit: str, bar) -> tuple:
    """The two certifications of ``crosscert certify``: under the stated bounds, then at the robot's own a_max.

    Returns ``(cert, figure, files, drawing)``: the certificate (the second run's comparison attached), the
    figure to draw (None: none), the files written so far, and the worker's drawing of the figure (None when
    it is to be drawn here).
    """
    # one worker process for both certifications' counterexample searches: the second reuses the
    # first's imports and NLP solvers (planner.refute builds one per sample count)
    pool = None if a.no_refute else SubprocessExecutor()
    drawing = None
    try:
        cert = certify_crossing(robot, task, bounds, v_low=a.v_low, v_high=a.v_high, tol=a.tol,
                                refute_tol=a.refute_tol, monte_carlo_runs=a.monte_carlo, refute=not a.no_refute, seed=a.seed,
                                progress=bar, kin=kin, executor=pool)
        figure = _figure(cert, robot, bounds, out, joint_unit)
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
        _close(pool, bar)
    return cert, figure, files, drawing


def _print_certify(a, cert, files: list, joint_unit: str) -> None:
    """The table and lines ``crosscert certify`` prints without ``--json``."""
    # widths are the forward tracker's boxes (the paper's Table II); the verdict includes the window passes
    print(f"{'v_sing (m/s)':>12} {'m_x (mm)':>10} {'m_xd (m/s)':>11} {'forward':>15} {'verdict':>15}")
    for r in cert.trials:
        print(f"{r.v_sing:12.4f} {1e3 * r.max_width_pose:10.2f} {r.max_width_velocity:11.3f} "
              f"{r.forward_verdict.value:>15} {r.verdict.value:>15}")
    vmin = "none (no tried speed certifies)" if cert.v_min is None else f"{cert.v_min:.4f} m/s"
    ref = _bound_text(cert.refutation_bound, cert.refutation_search, "m/s", 1.0, ".4f")
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
        fl = _bound_text(g.floor, g.floor_search, "mm", 1e3, ".2f")
        print(f"bounces at {g.speed:.4f} m/s turning back short of the locus: mode-unchanged certified from {cf}; "
              f"crossing floor (no sound tracker certifies at or closer): {fl}")
    if cert.monte_carlo is not None:
        print("Monte Carlo at v_min: " + monte_carlo_text(cert.monte_carlo))
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


#: The file ``certify`` writes the certified plan of a task to, in ``--out`` (its certificate names it).
CERTIFIED_PLAN = "certified_plan.csv"


def _write_plan(path: Path, plan) -> dict:
    """Write ``plan`` (t, q, x) and return the certificate's ``plan`` entry: its file name and sha256."""
    write_trajectory(path, plan.t, plan.q, x=plan.x)
    return PlanSource(path.name, hashlib.sha256(path.read_bytes()).hexdigest(), len(plan.t), float(plan.t_s),
                      "planned").summary()


def _bounds(a, entry, execution) -> PlanningBounds:
    """The certification's bounds from ``certify``'s options."""
    a_max = None if a.a_max is None else (a.a_max[0] if len(a.a_max) == 1 else a.a_max)
    xd0 = getattr(a, "xd0", None)
    return PlanningBounds(eps_q=a.eps_q, tracking_error=a.tracking_error, a_max=a_max, a_margin=a.a_margin,
                          a_peak=a.a_peak, method=a.method,
                          dynamics=entry.require_dynamics() if a.method == Method.DYNAMIC else None,
                          execution=execution, one_motion=a.one_motion, xd0=None if xd0 is None else tuple(xd0))


def _joint_unit(robot) -> str:
    units = {u.value for u in robot.joint_units}
    return units.pop() if len(units) == 1 else "rad or m (per joint)"


def _certify_given_plan(a) -> int:
    """``crosscert certify --plan FILE``: the verdict of the user's own plan, on the certificate's schema."""
    entry = get_entry(a.robot)
    robot = entry.robot
    bounds = _bounds(a, entry, a.execution or ExecutionKind.CARTESIAN)
    out = Path(a.out)
    bar = phase_bar(not a.no_progress, "certify")
    kin = kinematic_model(robot)
    retimed = None
    pool = None if a.no_refute or not a.retime else SubprocessExecutor()
    try:
        cert = certify_trajectory(robot, a.plan, bounds, initial_mode=a.initial_mode, execution=a.execution,
                                  monte_carlo_runs=a.monte_carlo, refute_plan=not a.no_refute, seed=a.seed,
                                  progress=bar, kin=kin)
        if a.retime:
            retimed = certify_path(robot, cert.trajectory, cert.bounds, source=a.plan, v_low=a.v_low, tol=a.tol,
                                   refute_tol=a.refute_tol, monte_carlo_runs=0, refute=not a.no_refute, seed=a.seed,
                                   progress=suffixed(bar, " of the re-timed path"), kin=kin, executor=pool)
    finally:
        _close(pool, bar)
    report = cert.summary()
    report["retimed_path"] = None if retimed is None else retimed.summary()
    report["command_line"] = ["crosscert", *a.argv]
    out.mkdir(parents=True, exist_ok=True)
    figure = _figure(cert, robot, cert.bounds, out, _joint_unit(robot))
    files = []
    if figure is not None:
        fn, *args, kwargs = figure[1]
        fn(*args, **kwargs)
        files.append(figure[0])
    if retimed is not None and retimed.trajectory is not None:
        p = retimed.trajectory
        files.append(out / f"retimed_plan_{retimed.v_min:.3f}.csv")
        write_trajectory(files[-1], p.t, p.q, x=p.x)
        report["retimed_path"]["plan_file"] = str(files[-1])
    if _write_report(out, report, files, a.json):
        return 0
    print(plan_verdict_line(cert) if retimed is None else retimed_line(cert, retimed))
    r = cert.trials[0]
    print(f"forward tracker: {r.forward_verdict.value}; widest boxes m_x {1e3 * r.max_width_pose:.2f} mm, "
          f"m_xd {r.max_width_velocity:.3f} m/s" + ("" if cert.window is None
                                                    else f"; window reasoning: {cert.window.verdict.value}"))
    if cert.monte_carlo is not None:
        print("Monte Carlo: " + monte_carlo_text(cert.monte_carlo))
    print(describe_execution(cert.execution, _joint_unit(robot)))
    print("a_max used: " + cert.a_max_used.describe())
    src = cert.plan_source
    print(f"plan: {src.file}, sha256 {src.sha256}, {src.samples} samples at t_s = {src.t_s:g} s, poses {src.poses}")
    print(f"elapsed {cert.elapsed_s:.1f} s ({', '.join(f'{k} {v:.1f}' for k, v in cert.timings_s.items())})")
    for f in files:
        print(f"wrote {f}")
    return 0


def plan_verdict_line(cert) -> str:
    """The one line a user acts on: the given plan's speed at the singularity, its verdict and, when it is not
    certified, what the counterexample search says."""
    r = cert.trials[0]
    head = f"your plan ({r.v_sing:.3f} m/s at the singularity): "
    if cert.verdict is Verdict.MODE_CHANGED:
        return head + "certified mode-changed for every admissible execution"
    if cert.verdict is Verdict.INCONSISTENT:
        return head + "inconsistent: the plan contradicts the bounds (no verdict)"
    text = head + f"not certified ({cert.verdict.value})"
    search = cert.refutation_search
    if search is None:
        return text + "; counterexample search not run"
    if search is SearchCompleteness.FOUND:
        return text + "; a verified counterexample explains its readings: no sound method certifies it"
    return text + "; counterexample on its readings: " + search.describe()


def retimed_line(cert, retimed) -> str:
    """The one line of ``certify --plan --retime``: the plan's verdict, the slowest speed at which its path
    certifies, and below which speed no sound method certifies it (or what that search rests on)."""
    r = cert.trials[0]
    line = f"your plan ({r.v_sing:.3f} m/s at the singularity): " + (
        "certified" if cert.verdict is Verdict.MODE_CHANGED else f"not certified ({cert.verdict.value})")
    if retimed.v_min is None:
        line += f"; this path certifies at no speed tried up to {max(t.v_sing for t in retimed.trials):.3f} m/s"
    else:
        line += f"; this path certifies from {retimed.v_min:.3f} m/s"
    search = retimed.refutation_search
    if search is None:
        return line
    if retimed.refutation_bound is not None:
        return line + f"; no sound method certifies it at or below {retimed.refutation_bound:.3f} m/s"
    return line + "; counterexamples on the path: " + search.describe()


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
    if at.refutation_search is not None:
        ref = _bound_text(at.refutation_bound, at.refutation_search, "m/s", 1.0, ".4f")
    print(f"at the robot's a_max ({robot_bound}): minimal certified v_sing {vmin}; refutation bound {ref}")


def _write_report(out: Path, report: dict, files: list, as_json: bool) -> bool:
    """Write ``certificate.json`` (appended to ``files``); with ``--json`` also print it and say so (True)."""
    js = out / "certificate.json"
    atomic_write(js, lambda fh: fh.write(json.dumps(report, indent=1)), what="--out")
    files.append(js)
    if as_json:
        print(json.dumps(report))
    return as_json


def _close(pool, bar) -> None:
    """Stop the counterexample worker (what it has not started is cancelled) and the progress bar."""
    if pool is not None:
        pool.shutdown(wait=False, cancel_futures=True)
    if bar is not None:
        bar.close()


def _bound_text(value, search, unit: str, scale: float, fmt: str) -> str:
    """A refutation bound or crossing floor with what it rests on: never "none found" for searches that all
    stopped at a limit (``search``: :class:`planner.refute.SearchCompleteness`, None when not run)."""
    if search is None:
        return "not computed"
    if value is None:
        return search.describe()
    return f"{format(scale * value, fmt)} {unit}"


def _figure(cert, robot, bounds, out: Path, joint_unit: str):
    """``(png path, (function, *args, kwargs))`` of the certificate's figure; None without a certifying run.

    The call is a module-level function with picklable arguments, so the worker process can draw it.
    """
    if cert.enclosures is None:
        return None
    e, p = cert.enclosures, cert.trajectory
    name = cert.robot_name
    given = cert.plan_source is not None
    v = cert.trials[0].v_sing if given else cert.v_min
    png = out / (f"certificate_{name}_plan.png" if given else f"certificate_{name}_{v:.3f}.png")
    subject = f"your plan at {v:.3f} m/s" if given else f"crossing at v_min = {v:.3f} m/s"
    done = "certified" if cert.verdict is Verdict.MODE_CHANGED else f"{cert.verdict.value} after"

    def what(by):
        return f"{subject} {done} by {by}" if done == "certified" else f"{subject}: {done} {by}"

    forward = {"x_lo": e.x_lo, "x_hi": e.x_hi, "xd_lo": e.xd_lo, "xd_hi": e.xd_hi, "mode": e.mode}
    if cert.window is not None:
        # the certified run as the online monitor reports it: after its window's decision, the decided mode's
        # boxes (the forward pass alone keeps both modes to the end); from the forward run's box at sample 0
        model = interval_model(robot)
        forward = online_boxes(model, p.q, e.settings, (e.x_lo[0], e.x_hi[0]),
                               xi_box=None if cert.execution is None else cert.execution.xi_box)
    text = (f"{'given' if given else bounds.method} plan, eps_q = {cert.bounds.eps_q:.3g} {joint_unit}, a_max = "
            f"({', '.join(f'{x.value:.4g} {x.unit}' for x in cert.a_max_used.axes)}), "
            f"t_s = {cert.bounds.t_s:.3g} s, "
            f"{cert.execution.kind.value} executions")
    if cert.window is not None:  # the window passes certified: draw them, the forward pass only beside them
        call = (plot_certificate, png, p.t_s, {k: forward[k] for k in ("x_lo", "x_hi", "xd_lo", "xd_hi", "mode")},
                cert.window, p.x, p.xd, p.k_sing,
                {"title": f"{name}: {what('window reasoning')}", "bounds": text,
                 "forward_label": "online (tracker, then the decided mode)"})
    else:
        call = (plot_run, png, p.t_s, forward, p.x, p.xd, p.k_sing,
                {"title": f"{name}: {what('the forward pass')}",
                 "truth": "planned", "bounds": text})
    return png, call


def monte_carlo_text(mc) -> str:
    """The Monte Carlo row: what the run-time tracker decided, what the certificate covers, and what the
    readings let a run-time check confirm (``monitor --certificate``)."""
    text = (f"{mc.detected_in_class}/{mc.in_class} admissible executions also decided by the run-time tracker "
            f"alone ({mc.detected}/{mc.runs} in all; every admissible one is covered by the certificate)")
    if mc.envelope_checked:
        text += (f"; {mc.covered_at_run_time}/{mc.runs} with readings inside the certified envelope, where "
                 "`monitor --certificate` confirms the certificate's verdict at run time")
        if mc.covered_at_run_time < mc.runs:
            text += " (the others' readings leave it: docs/planning.md, \"What it covers in practice\")"
    return (text + f", {len(mc.containment_failures)} containment failures, {len(mc.wrong_verdicts)} wrong "
            "verdicts")
