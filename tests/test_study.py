"""Design studies and large Monte Carlo runs on Dask: same results as serial, restartable, robust to a dead worker."""

import os
import signal
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from crosscert.planner import PlanningBounds, plan_crossing  # noqa: E402
from crosscert.planner.execution_proof import execution_class  # noqa: E402
from crosscert.planner.montecarlo import monte_carlo_confirmation  # noqa: E402
from crosscert.planner.study import run_study, read_results, run_case, study_cases  # noqa: E402
from crosscert.robots.errors import InputError  # noqa: E402

#: Cheap certifications: no refutation, no Monte Carlo, a coarse speed resolution (~3 s a case).
FAST = {"refute": False, "monte_carlo_runs": 0, "tol": 0.05}
GRID = {"a_max": [70.0, 100.0], "width_scale": [0.5, 1.0]}


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


def _by_case(table):
    return {r.case_id: r for r in table.itertuples()}


def test_a_study_on_dask_equals_the_same_cases_run_serially(client, tmp_path):
    table = run_study(GRID, out=tmp_path / "s.csv", certify=FAST, client=client)
    assert len(table) == 4 and table["error"].isna().all()
    settings = {"robot": "dextar", "bounds": {}, "certify": FAST}
    cases = study_cases(GRID)
    for case in (cases[0], cases[-1]):  # two of the four re-run here (each a certification): the first and the last
        row = _by_case(table)[case.case_id]
        serial = run_case(case, settings)
        assert row.v_min_mps == pytest.approx(serial["v_min_mps"], abs=0) and row.verdict == serial["verdict"]
    # narrower calibration boxes certify slower crossings; a larger a_max needs faster ones
    v = {(r.a_max, r.width_scale): r.v_min_mps for r in table.itertuples()}
    assert v[(70.0, 0.5)] < v[(70.0, 1.0)] < v[(100.0, 1.0)]


def test_a_rerun_skips_what_is_done(tmp_path):
    out = tmp_path / "s.csv"
    grid = {"a_max": [80.0]}
    first = run_study(grid, out=out, certify=FAST, executor=ThreadPoolExecutor(1))

    class Refusing(ThreadPoolExecutor):
        def submit(self, *args, **kwargs):
            raise AssertionError("a finished case was run again")

    again = run_study(grid, out=out, certify=FAST, executor=Refusing(1))
    assert len(read_results(out)) == 1 and again["v_min_mps"].tolist() == first["v_min_mps"].tolist()


def test_a_failing_case_is_a_row_not_a_lost_study(tmp_path):
    table = run_study({"a_max": [1.0, 80.0]}, out=tmp_path / "s.csv", certify=FAST, executor=ThreadPoolExecutor(2))
    errors = table.set_index("a_max")["error"]
    assert "no feasible crossing speed" in errors[1.0] and not isinstance(errors[80.0], str)


def test_a_dead_worker_loses_only_its_case(client, tmp_path):
    """A worker process is killed while the study runs: the scheduler runs its case again; every case ends."""
    pids = client.run(os.getpid)
    killed = []

    def kill_one(_row):
        if not killed:
            pid = next(iter(pids.values()))
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    grid = {"a_max": [65.0, 75.0, 85.0, 95.0], "width_scale": [1.0]}
    table = run_study(grid, out=tmp_path / "s.csv", certify=FAST, client=client, progress=kill_one)
    assert killed and len(table) == 4 and table["error"].isna().all()
    assert np.isfinite(table["v_min_mps"]).all()


def test_bad_grids_are_refused_before_any_work(tmp_path):
    for grid, message in (({"speed": [1]}, "unknown study input"), ({"a_max": []}, "no values"),
                          ({"a_max": [-1.0]}, "a_max"), ({"method": ["fast"]}, "unknown method"),
                          ({"robot": ["delta"]}, "unknown robot")):
        with pytest.raises(InputError, match=message):
            run_study(grid, out=tmp_path / "s.csv", executor=ThreadPoolExecutor(1))
    assert not (tmp_path / "s.csv").exists()


def test_monte_carlo_in_batches_on_dask_equals_one_batch(client, kin, imodel, task):
    b = PlanningBounds().resolve(kin.robot)
    plan = plan_crossing(kin, task, 1.3, b)
    cls = execution_class(kin, plan, b)
    one = monte_carlo_confirmation(kin, imodel, plan, b, runs=12, seed=3, execution=cls)
    split = monte_carlo_confirmation(kin, imodel, plan, b, runs=12, seed=3, execution=cls,
                                     executor=client.get_executor(pure=False), batch_runs=5)
    assert one.summary() == split.summary()
    assert one.runs == 12 and one.containment_failures == () and one.wrong_verdicts == ()


def test_the_crossing_point_moves_along_the_locus(tmp_path):
    """``crossing_offset`` moves the task across its direction: it still crosses, at another point of the locus."""
    table = run_study({"crossing_offset": [0.0, 0.02]}, out=tmp_path / "s.csv", certify=FAST,
                         executor=ThreadPoolExecutor(2))
    v = table.set_index("crossing_offset")["v_min_mps"]
    assert table["error"].isna().all() and np.isfinite(v).all() and v[0.0] != v[0.02]
