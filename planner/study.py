"""Design studies: how v_min and the refutation floor move with the bounds, on Dask or any executor.

A study is a grid of inputs (:data:`GRID_KEYS`); each point is one
certification (:func:`planner.certify.crossing.certify_crossing`) of a robot's
benchmark task, run where the caller says:

* a ``dask.distributed`` client (``client=``, or ``scheduler="tcp://host:8786"``),
* any ``concurrent.futures`` executor (``executor=``),
* or, with neither, a ``LocalCluster`` sized to the machine.

Each finished case is appended to the output CSV as it arrives, so a study
that stops loses nothing done: run it again with the same output and the
finished cases are skipped.  A last row cut short (the process killed while
writing it, a full disk) is cut off the file by :func:`repair_results`
before anything is appended, and its case runs again; a malformed row
elsewhere is ignored, so a case never has two rows.  A case that raises becomes a row with its error.
A worker that dies loses only the case it was running: the Dask scheduler
runs it again elsewhere (``distributed.scheduler.allowed-failures`` times).
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import itertools
import json
import logging
import os
import time
from collections.abc import Callable, Iterable
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crosscert.robots import arguments as V
from crosscert.robots.errors import InputError, ModelError
from crosscert.robots.registry import DEFAULT_ROBOT, get_entry, robot_key

from .certify.certificate import package_versions
from .certify.crossing import certify_crossing
from .task import Method, PlanningBounds, benchmark_task, parse_option

__all__ = ["GRID_KEYS", "StudyCase", "study_cases", "run_case", "run_study", "read_results", "repair_results",
           "scaled_box"]

log = logging.getLogger(__name__)

#: What a grid may span, with the unit of its values.
GRID_KEYS = {
    "a_max": "every axis, in its unit (m/s^2): robots whose pose axes share one unit (absent: derived per axis)",
    "width_scale": "scale of every calibration half-width around the box centre",
    "width_scale.lengths": "scale of the half-widths of the parameters that are not joint offsets",
    "width_scale.offsets": "scale of the half-widths of the joint-offset parameters",
    "eps_q": "encoder error bound, rad",
    "crossing_offset": "m: the benchmark task moved across its direction, so it crosses the locus elsewhere",
    "method": "time law: smoothstep, time-optimal or dynamic",
    "robot": "a registered robot with a benchmark crossing",
}
#: Columns of a result row, in order (inputs first; a missing input is empty).
COLUMNS = (["case_id"] + list(GRID_KEYS) + ["v_min_mps", "refutation_bound_mps", "verdict", "trials", "a_max_used",
                                            "elapsed_s", "error", "versions"])


@dataclass(frozen=True)
class StudyCase:
    """One point of a grid: the values of the swept inputs (the others keep the base settings)."""

    inputs: tuple  # sorted (key, value) pairs

    @property
    def values(self) -> dict:
        return dict(self.inputs)

    @property
    def case_id(self) -> str:
        """A stable name of the inputs: the same case has the same id in every run of a study."""
        text = json.dumps(self.inputs, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def study_cases(grid: dict) -> list[StudyCase]:
    """The cartesian product of ``grid`` (``{key: [values]}``, keys of :data:`GRID_KEYS`) as cases.

    Raises
    ------
    InputError
        An unknown key, an empty list, or a value of the wrong kind.
    """
    if not isinstance(grid, dict) or not grid:
        raise InputError("a study grid is a non-empty mapping {input: [values]}")
    axes = []
    for key in sorted(grid):
        if key not in GRID_KEYS:
            raise InputError(f"unknown study input {key!r}; use one of {', '.join(GRID_KEYS)}")
        values = grid[key] if isinstance(grid[key], (list, tuple)) else [grid[key]]
        if not values:
            raise InputError(f"study input {key!r} has no values")
        axes.append([(key, _value(key, v)) for v in values])
    return [StudyCase(tuple(combo)) for combo in itertools.product(*axes)]


def _value(key: str, v):
    if key == "method":
        return parse_option(Method, "method", v).value
    if key == "robot":  # a robot file by its absolute path, so that every worker finds it
        return robot_key(v)
    if key == "crossing_offset":
        return V.number(key, v)
    return V.positive(key, v)


def scaled_box(robot, scale_lengths: float = 1.0, scale_offsets: float = 1.0):
    """``robot`` with the half-widths of ``[xi]`` scaled around the box centre, per parameter group.

    The offsets group is the parameters ``robot.joint_offsets`` names.  The
    nominal geometry is kept when the robot still accepts it, else it becomes
    the centre (neither the planner nor the tracker reads it).
    """
    offsets = {j for j in (robot.joint_offsets or ()) if j is not None}
    scale = np.array([scale_offsets if i in offsets else scale_lengths for i in range(robot.m)])
    lo, hi = robot.xi_lo_array, robot.xi_hi_array
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    new_lo = tuple(float(v) for v in centre - scale * half)
    new_hi = tuple(float(v) for v in centre + scale * half)
    try:
        return dataclasses.replace(robot, xi_lo=new_lo, xi_hi=new_hi)
    except ModelError:
        return dataclasses.replace(robot, xi_lo=new_lo, xi_hi=new_hi, xi_nominal=tuple(float(v) for v in centre))


def run_case(case: StudyCase, settings: dict) -> dict:
    """Certify one case; a result row (never raises: an error becomes the row's ``error``).

    ``settings``: ``robot`` (default), ``bounds`` (``PlanningBounds`` keyword
    arguments) and ``certify`` (keyword arguments of ``certify_crossing``).
    """
    v = case.values
    row = {"case_id": case.case_id, **{k: v.get(k, "") for k in GRID_KEYS}, "error": "",
           "versions": json.dumps(package_versions(), sort_keys=True)}
    t0 = time.perf_counter()
    try:
        entry = get_entry(v.get("robot", settings.get("robot", DEFAULT_ROBOT)))
        lengths = v.get("width_scale.lengths", v.get("width_scale", 1.0))
        offsets = v.get("width_scale.offsets", v.get("width_scale", 1.0))
        robot = scaled_box(entry.robot, lengths, offsets)
        task = benchmark_task(entry)
        shift = float(v.get("crossing_offset", 0.0))
        if shift:
            b = entry.benchmark_crossing()
            across = np.linalg.svd(b.direction[None, :])[2][-1]  # a unit vector normal to the direction
            task = dataclasses.replace(task, start=task.start + shift * across, goal=task.goal + shift * across)
        kw = dict(settings.get("bounds", {}))
        if "a_max" in v:
            # one number for every axis: PlanningBounds refuses it for a robot whose axes mix m and rad
            kw["a_max"] = float(v["a_max"])
            kw["a_peak"] = min(kw.get("a_peak", PlanningBounds().a_peak), float(v["a_max"]))
        if "eps_q" in v:
            kw["eps_q"] = float(v["eps_q"])
        if "method" in v:
            kw["method"] = v["method"]
        if kw.get("method") == Method.DYNAMIC:
            kw["dynamics"] = entry.require_dynamics()
        # a study sweeps v_min and the refutation bound: the bounce gap is asked for explicitly
        cert = certify_crossing(robot, task, PlanningBounds(**kw), **{"bounce": False, **settings.get("certify", {})})
        row.update(v_min_mps=cert.v_min, refutation_bound_mps=cert.refutation_bound, verdict=cert.verdict.value,
                   trials=len(cert.trials),
                   a_max_used="" if cert.a_max_used is None else json.dumps(cert.a_max_used.summary()))
    except Exception as exc:  # one bad case must not lose the study
        row.update(v_min_mps="", refutation_bound_mps="", verdict="", trials="", a_max_used="",
                   error=f"{type(exc).__name__}: {exc}")
    row["elapsed_s"] = round(time.perf_counter() - t0, 3)
    return row


def run_cases(cases: list[StudyCase], settings: dict) -> list[dict]:
    """Several cases in one task (cheap cases: Dask's per-task overhead is ~1 ms)."""
    return [run_case(c, settings) for c in cases]


def _complete(row: list) -> bool:
    """A CSV record is a whole result row: every column, and the versions JSON object that ends it."""
    if len(row) != len(COLUMNS):
        return False
    try:
        return isinstance(json.loads(row[-1]), dict)
    except ValueError:
        return False


def _records(path: Path):
    """``(record, end)`` for each CSV record of ``path``: its cells and the byte offset just after it."""
    with path.open(newline="", encoding="utf-8", errors="surrogateescape") as fh:
        end = 0

        def lines():
            nonlocal end
            for line in fh:
                end += len(line.encode("utf-8", errors="surrogateescape"))
                yield line

        reader = csv.reader(lines())
        try:
            for row in reader:
                yield row, end
        except csv.Error:  # e.g. a NUL byte: the rest is one malformed record
            yield [], path.stat().st_size


def read_results(path) -> list[dict]:
    """The whole result rows already in a study's CSV, as dicts of text (malformed rows are left out)."""
    p = Path(path)
    if not p.exists():
        return []
    rows = [r for r, _ in _records(p)]
    return [dict(zip(COLUMNS, r)) for r in rows[1:] if _complete(r)]


def repair_results(path) -> str | None:
    """Cut a torn last row off a study's CSV; return what was done (a warning to show), or None.

    A row is torn when the process writing it was killed, or the disk filled,
    before its end: it lacks columns or its closing versions field.  Rows
    are appended one whole line at a time, so only the last one can be torn;
    it is cut off (the file is truncated in place, its mode kept) so that the
    next row starts on a line of its own, and its case, no longer in the
    file, runs again.  A last row complete but for its line end gets one.
    """
    p = Path(path)
    if not p.is_file() or p.stat().st_size == 0:
        return None
    records = list(_records(p))
    size = p.stat().st_size
    if len(records) < 2:
        return None
    row, _ = records[-1]
    keep = records[-2][1]
    if _complete(row):
        with p.open("rb") as fh:
            fh.seek(size - 1)
            last = fh.read(1)
        if last not in (b"\n", b"\r"):
            with p.open("ab") as fh:
                fh.write(b"\r\n")
        return None
    with p.open("rb") as fh:
        fh.seek(keep)
        torn = fh.read(size - keep)
    os.truncate(p, keep)
    text = torn.decode("utf-8", errors="replace").strip()
    shown = text if len(text) <= 60 else text[:57] + "..."
    return (f"{p}: its last row was cut short ({len(torn)} bytes: {shown!r}), probably by a process killed while "
            "writing it; the row was removed and its case runs again")


def _append(path: Path, rows: Iterable[dict]) -> None:
    new = not path.exists() or path.stat().st_size == 0
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        if new:
            w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in COLUMNS})
        fh.flush()
        os.fsync(fh.fileno())


def run_study(grid: dict, *, out, robot: str = DEFAULT_ROBOT, bounds: dict | None = None,
                 certify: dict | None = None, client=None, scheduler: str | None = None,
                 executor: Executor | None = None, workers: int | None = None, cases_per_task: int = 1,
                 progress: Callable[[dict], None] | None = None):
    """Run a design study; return its table (a pandas DataFrame, one row per case).

    Parameters
    ----------
    grid : dict
        ``{input: [values]}`` over :data:`GRID_KEYS`; every combination is a case.
    out : str or Path
        CSV file the rows are appended to as they finish; cases already in it
        are skipped (restart), so one output belongs to one study.
    robot : str
        Robot of the cases that do not sweep ``robot``.
    bounds, certify : dict, optional
        Keyword arguments of ``PlanningBounds`` and of ``certify_crossing``
        common to every case (e.g. ``{"refute": False, "tol": 0.02}``).
    client : dask.distributed.Client, optional
        Where the cases run.  ``scheduler``: the address of one to connect to.
        ``executor``: any ``concurrent.futures.Executor`` instead of Dask.
        None of them: a ``LocalCluster`` of ``workers`` single-threaded worker
        processes (default: one per core), closed at the end.
    cases_per_task : int
        Cases run in one task (1: a certification is seconds, far above the
        ~1 ms Dask overhead; more for very cheap cases).
    progress : callable, optional
        ``progress(row)`` as each case finishes.
    """
    import pandas as pd

    out = _output(out)
    per_task = int(V.number("cases_per_task", cases_per_task, lo=1))
    settings = {"robot": robot, "bounds": dict(bounds or {}), "certify": dict(certify or {})}
    cases = study_cases(grid)
    todo = _pending(cases, out)
    batches = [todo[i:i + per_task] for i in range(0, len(todo), per_task)]
    if batches:
        own = None
        if executor is None:
            executor, own = _dask_executor(client, scheduler, workers)
        _run_batches(executor, batches, settings, out, progress, own)
    text = io.StringIO()
    w = csv.DictWriter(text, fieldnames=COLUMNS)
    w.writeheader()
    w.writerows(read_results(out))  # whole rows only: a malformed line is no row
    text.seek(0)
    table = pd.read_csv(text, dtype={"case_id": str}, keep_default_na=True)
    table = table[table["case_id"].isin({c.case_id for c in cases})]
    return table.drop_duplicates("case_id", keep="last").reset_index(drop=True)


def _output(out) -> Path:
    """The study's CSV path, checked: it ends in ``.csv`` and its folder exists (else :class:`InputError`)."""
    out = Path(out)
    if out.suffix.lower() != ".csv":
        raise InputError(f"a study writes CSV: {out} must end in .csv")
    if not out.parent.is_dir():
        raise InputError(f"folder {out.parent} does not exist")
    return out


def _pending(cases: list[StudyCase], out: Path) -> list[StudyCase]:
    """The cases not yet in ``out``, after cutting a torn last row off it (logged as a warning)."""
    torn = repair_results(out)
    if torn is not None:
        log.warning("%s", torn)
    done = {r["case_id"] for r in read_results(out)}
    todo = [c for c in cases if c.case_id not in done]
    log.info("study: %d cases, %d already in %s", len(cases), len(cases) - len(todo), out)
    return todo


def _dask_executor(client, scheduler: str | None, workers: int | None):
    """An executor of the Dask client, connected to ``scheduler`` or a new ``LocalCluster`` if there is none.

    Returns
    -------
    executor : concurrent.futures.Executor
    own : dask.distributed.Client or None
        The client made here (to be closed at the end), None for the caller's ``client``.

    Raises
    ------
    InputError
        A malformed scheduler address, or no scheduler answering there.
    """
    own = None
    if client is None:
        from dask.distributed import Client, LocalCluster

        if scheduler is not None:
            try:
                client = own = Client(scheduler)
            except ValueError as exc:  # a malformed address
                raise InputError(f"scheduler {scheduler!r}: {exc}") from None
            except OSError as exc:  # nobody answers there (after distributed.comm.timeouts.connect)
                raise InputError(f"cannot reach the Dask scheduler at {scheduler} ({exc}); start it "
                                 "(dask scheduler) or check the address") from None
        else:
            # dashboard on a free port: a second study on the machine must not collide
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                                   processes=True, dashboard_address=":0")
            try:
                client = own = Client(cluster)
            except BaseException:
                cluster.close()  # no client to close it with
                raise
    try:
        return client.get_executor(pure=False), own
    except BaseException:
        _close(own)
        raise


def _close(own) -> None:
    """Close ``own``, a Dask client made for the study, and its cluster (nothing for None)."""
    if own is not None:
        cluster = getattr(own, "cluster", None)
        own.close()
        if cluster is not None:
            cluster.close()


def _run_batches(executor: Executor, batches: list[list[StudyCase]], settings: dict, out: Path,
                 progress: Callable[[dict], None] | None, own) -> None:
    """Run the batches on ``executor``, appending each one's rows to ``out`` as it finishes.

    ``own``, a Dask client made for the study (or None), is closed at the
    end with its cluster, whatever happens.
    """
    try:
        futures = [executor.submit(run_cases, b, settings) for b in batches]
        for f in as_completed(futures):
            rows = f.result()
            _append(out, rows)
            for r in rows:
                if progress is not None:
                    progress(r)
    finally:
        _close(own)
