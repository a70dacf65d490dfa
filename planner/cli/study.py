"""``crosscert study``: a design study (:func:`planner.study.run_study`) from a TOML grid, on Dask.

The grid file (read with :mod:`tomllib`)::

    robot = "NAME"              # optional: a registered robot for every case (wins over --robot)
    [grid]                      # every combination of these values is one case
    a_max = [70.0, 100.0]       # keys of planner.study.GRID_KEYS
    width_scale = [0.5, 1.0]
    [bounds]                    # optional: PlanningBounds keyword arguments shared by every case
    a_peak = 60.0
    [certify]                   # optional: certify_crossing keyword arguments (CERTIFY_KEYS only)
    tol = 0.02

``width_scale.lengths`` may be written quoted (``"width_scale.lengths" = [...]``)
or as a sub-table (``[grid.width_scale] lengths = [...]``): nested tables are
flattened with dots.
"""

from __future__ import annotations

import math
import sys
import textwrap
import time
import tomllib
from pathlib import Path

from crosscert.robots.errors import InputError
from crosscert.verifier.files import atomic_write

from ..study import GRID_KEYS, run_study, read_results, repair_results, study_cases
from .setup import progress_bar

__all__ = ["study", "read_grid", "plot_study", "CERTIFY_KEYS", "BOUNDS_KEYS", "MAX_GRID_BYTES"]

#: Sections and keys a grid file may have at its top level.
TOP_KEYS = ("robot", "grid", "bounds", "certify")
#: ``[certify]`` keys (keyword arguments of ``certify_crossing``) a study may set.
CERTIFY_KEYS = ("tol", "refute_tol", "v_low", "v_high", "monte_carlo_runs", "refute", "seed", "bounce")
#: ``[bounds]`` keys (``PlanningBounds`` fields; ``dynamics`` comes from the robot for ``method = "dynamic"``).
BOUNDS_KEYS = ("eps_q", "tracking_error", "a_max", "a_margin", "a_peak", "t_s", "t_rest", "method", "qd_max",
               "qdd_max", "execution", "reasoning", "one_motion")
#: Largest grid file read, bytes (a grid of 10 000 cases fits in a few kB).
MAX_GRID_BYTES = 1 << 20
#: Inputs whose values are names, not numbers: they label the plot's series instead of getting a panel.
NAMED_INPUTS = ("method", "robot")
#: Characters of a case's error shown in the summary table.
ERROR_WIDTH = 60


def _flatten(table: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _section(data: dict, name: str, path) -> dict:
    sec = data.get(name, {})
    if not isinstance(sec, dict):
        raise InputError(f"{path}: [{name}] must be a table")
    return sec


def read_grid(path) -> dict:
    """The study a TOML grid file describes: ``{"robot", "grid", "bounds", "certify"}``.

    ``robot`` is None when the file names none; ``grid`` is flattened
    (``{input: [values]}``) and checked with :func:`planner.study.study_cases`;
    ``bounds`` and ``certify`` are dicts (empty when absent) whose keys are
    checked against :data:`BOUNDS_KEYS` and :data:`CERTIFY_KEYS` and whose
    values have the right kind (ranges: :mod:`planner.cli.checks`).

    Raises
    ------
    InputError
        A missing, unreadable or oversized file, invalid TOML, or a bad section, key or value.
    """
    p = Path(path)
    try:
        if p.stat().st_size > MAX_GRID_BYTES:
            raise InputError(f"{path}: {p.stat().st_size} bytes; a grid file is at most {MAX_GRID_BYTES} bytes")
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path} is a directory, not a TOML grid file") from None
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        msg = " ".join(str(exc).split())
        raise InputError(f"{path} is not valid TOML: {msg}") from None
    unknown = sorted(set(data) - set(TOP_KEYS))
    if unknown:
        raise InputError(f"{path}: unknown entry {unknown[0]!r}; a grid file has {', '.join(TOP_KEYS)}")
    robot = data.get("robot")
    if robot is not None and not isinstance(robot, str):
        raise InputError(f"{path}: robot must be a name (a string), got {robot!r}")
    if "grid" not in data:
        raise InputError(f"{path}: no [grid] table (the inputs to sweep: {', '.join(GRID_KEYS)})")
    grid = _flatten(_section(data, "grid", path))
    study_cases(grid)  # unknown input, empty list, value of the wrong kind
    bounds = _section(data, "bounds", path)
    for k in bounds:
        if k not in BOUNDS_KEYS:
            raise InputError(f"{path}: unknown [bounds] key {k!r}; allowed: {', '.join(BOUNDS_KEYS)}")
    certify = _section(data, "certify", path)
    for k, v in certify.items():
        if k not in CERTIFY_KEYS:
            raise InputError(f"{path}: [certify] key {k!r} is not allowed; allowed: {', '.join(CERTIFY_KEYS)}")
        if k in ("refute", "bounce") and not isinstance(v, bool):
            raise InputError(f"[certify] {k} must be true or false, got {v!r}")
        if k in ("monte_carlo_runs", "seed") and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
            raise InputError(f"[certify] {k} must be a non-negative whole number, got {v!r}")
        if k in ("tol", "refute_tol", "v_low", "v_high") and (isinstance(v, bool) or not isinstance(v, (int, float))
                                                              or not math.isfinite(v)):
            raise InputError(f"[certify] {k} must be a finite number (m/s), got {v!r}")
    return {"robot": robot, "grid": grid, "bounds": dict(bounds), "certify": dict(certify)}


def _fmt(v) -> str:
    if isinstance(v, float):
        return "-" if math.isnan(v) else f"{v:g}"
    return str(v)


def _speed(v) -> str:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return "-"
    return "-" if math.isnan(f) else f"{f:.4f}"


def _error(v) -> str:
    if not isinstance(v, str) or not v:
        return ""
    v = " ".join(v.split())
    return v if len(v) <= ERROR_WIDTH else v[:ERROR_WIDTH - 3] + "..."


def study(a) -> int:
    """``crosscert study``: run the grid of ``a.grid`` into ``a.output``, print a table, optionally plot it."""
    t0 = time.perf_counter()
    spec = getattr(a, "spec", None) or read_grid(a.grid)
    robot = spec["robot"] or a.robot
    grid = spec["grid"]
    cases = study_cases(grid)
    torn = repair_results(a.output)
    if torn is not None:
        print(f"crosscert: warning: {torn}", file=sys.stderr)
    done = {r["case_id"] for r in read_results(a.output)}
    todo = sum(c.case_id not in done for c in cases)
    bar, cb = progress_bar(todo, not a.no_progress and todo > 0, "study")
    if bar is not None:
        bar.unit = "case"
        bar.refresh()
    try:
        table = run_study(grid, out=a.output, robot=robot, bounds=spec["bounds"], certify=spec["certify"],
                             scheduler=a.scheduler, workers=a.workers, progress=cb)
    finally:
        if bar is not None:
            bar.close()
    order = {c.case_id: i for i, c in enumerate(cases)}
    table = table.assign(_order=table["case_id"].map(order)).sort_values("_order").drop(columns="_order")
    swept = sorted(grid)
    widths = [max(len(k), 10) for k in swept]
    head = " ".join(f"{k:>{w}}" for k, w in zip(swept, widths))
    print(f"{head} {'v_min (m/s)':>11} {'refutation (m/s)':>16} {'verdict':>15} {'elapsed (s)':>11}  error")
    for _, r in table.iterrows():
        ins = " ".join(f"{_fmt(r[k]):>{w}}" for k, w in zip(swept, widths))
        verdict = r["verdict"] if isinstance(r["verdict"], str) else "-"
        print(f"{ins} {_speed(r['v_min_mps']):>11} {_speed(r['refutation_bound_mps']):>16} {verdict:>15} "
              f"{float(r['elapsed_s']):>11.1f}  {_error(r['error'])}".rstrip())
    errors = int(sum(isinstance(e, str) and bool(e) for e in table["error"]))
    if a.plot is not None:
        plot_study(a.plot, table, swept, robot=robot)
    print(f"{_n(len(cases), 'case')} ({len(cases) - todo} already in {a.output}, {todo} run now), "
          f"{_n(errors, 'error')}; "
          f"wall time {time.perf_counter() - t0:.1f} s")
    print(f"wrote {a.output}")
    if a.plot is not None:
        print(f"wrote {a.plot}")
    return 0


def _n(k: int, what: str) -> str:
    return f"{k} {what}" + ("" if k == 1 else "s")


def _label(r, keys) -> str:
    return ", ".join(f"{k} = {_fmt(r[k])}" for k in keys)


def plot_study(path, table, swept, *, robot: str) -> Path:
    """Write a PNG: one panel per swept numeric input, v_min (filled) and refutation bound (hollow) against it.

    Parameters
    ----------
    path : str or Path
        Output PNG, written by :func:`verifier.files.atomic_write`.
    table : pandas.DataFrame
        Rows of :func:`planner.study.run_study`.
    swept : list of str
        The grid's inputs.  Each numeric one gets a panel; one series per
        combination of the other inputs (names, like ``method``, only label
        series).  Without numeric inputs, one panel with a point per case.
    robot : str
        The robot of the cases that do not sweep ``robot`` (for the title).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    numeric = [k for k in swept if k not in NAMED_INPUTS]
    panels = numeric or [None]
    fig, axes = plt.subplots(1, len(panels), figsize=(5.4 * len(panels), 4.6), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    rows = [r for _, r in table.iterrows()]
    refuted = any(math.isfinite(float(r["refutation_bound_mps"])) for r in rows)
    for ax, key in zip(axes[0], panels):
        others = [k for k in swept if k != key]
        series: dict[str, list] = {}
        for r in rows:
            series.setdefault(_label(r, others), []).append(r)
        for i, (label, rs) in enumerate(series.items()):
            c = colors[i % len(colors)]
            if key is None:
                xs = [i] * len(rs)
            else:
                rs = sorted(rs, key=lambda r: float(r[key]))
                xs = [float(r[key]) for r in rs]
            vmin = [float(r["v_min_mps"]) for r in rs]
            ref = [float(r["refutation_bound_mps"]) for r in rs]
            ax.plot(xs, vmin, marker="o", ls="-" if key is not None else "", color=c, label=label or "v_min")
            if any(math.isfinite(v) for v in ref):
                ax.plot(xs, ref, marker="o", mfc="none", ls=":" if key is not None else "", color=c)
        if key is None:
            ax.set_xticks(range(len(series)), list(series), rotation=20, ha="right", fontsize=7)
            ax.set_xlabel("case")
        else:
            ax.set_xlabel(textwrap.fill(f"{key}: {GRID_KEYS[key]}", 50), fontsize=8)
        ax.set_ylabel("speed at the singularity (m/s)")
        ax.grid(True, alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        if refuted:
            handles += [Line2D([], [], color="0.3", marker="o", ls="", label="filled: v_min (certified)"),
                        Line2D([], [], color="0.3", marker="o", mfc="none", ls="", label="hollow: refutation bound")]
        ax.legend(handles=handles, fontsize=7, loc="best")
    robots = sorted({str(r["robot"]) for r in rows}) if "robot" in swept else [robot]
    fig.suptitle(f"design study: {', '.join(robots)}, {_n(len(rows), 'case')}")
    fig.tight_layout()
    try:
        return atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110), binary=True, what="--plot")
    finally:
        plt.close(fig)
