"""Recordings other than CSV through the CLI: ROS 2 bags (.mcap, .db3, a bag's folder) and .npz files.

The bags are written here with rosbags' writer: ``sensor_msgs/msg/JointState``
on ``/joint_states``, the joints named in an order of their own (two orders,
alternating) with a joint the robot does not have.  Each format's verdict is
the verdict of the same readings as CSV; what a user can get wrong is one line
on stderr and exit 2.  A bag of an adversarial crossing sampled at jittered
times, its header stamps off the truth by up to ``--stamp-error`` and one
message dropped, gets the verdict of the same motion sampled every period, with
the truth inside every box (:mod:`verifier.clock`).
"""

import contextlib
import io
import json
import sys

import numpy as np
import pytest

from adversarial import near_scenarios
from problems import CATALOGUE, interval_model, run_of
from crosscert.planner.cli import main
from crosscert.robots import DEXTAR
from crosscert.verifier.tracker import Tracker, TrackerSettings, initial_box_from_mode
from crosscert.verifier.window import online_boxes
from crosscert.robots.errors import TrajectoryFileError
from crosscert.verifier.recordings import NpzReader, open_recording
from crosscert.verifier.trajfile import write_trajectory

FLAGS = ["--initial-mode", "1", "--json", "--no-progress"]
JOINTS = "left_motor,right_motor"
#: Names in the messages: q2, an extra joint, q1 (and the other order on every other message).
ORDERS = (("right_motor", "tool_roll", "left_motor"), ("tool_roll", "left_motor", "right_motor"))
#: A Unix-epoch start of the header stamps, ns.
EPOCH_NS = 1_700_000_000_123_456_789


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err and "\n" not in err and "Traceback" not in err, err
    return err


def _verdict(capsys, *argv) -> dict:
    """``check`` in-process: the JSON summary without its wall-clock times."""
    assert main(["check", *map(str, argv), *FLAGS]) == 0
    out = json.loads(capsys.readouterr().out)
    out.pop("elapsed_s")
    if out.get("window"):
        out["window"].pop("elapsed_s", None)
    return out


@pytest.fixture(scope="module")
def crossing():
    """A simulated crossing at 1.458 m/s (mode-changed): (t s, q_meas rad)."""
    run = run_of(CATALOGUE["crossing_1458"])
    return run.t, run.q_meas


@pytest.fixture(scope="module")
def csv_verdict(crossing, tmp_path_factory):
    path = tmp_path_factory.mktemp("csv") / "crossing.csv"
    write_trajectory(path, *crossing)
    text = io.StringIO()
    with contextlib.redirect_stdout(text):  # capsys is per test
        assert main(["check", str(path), *FLAGS]) == 0
    out = json.loads(text.getvalue())
    out.pop("elapsed_s")
    return out


def _write_bag(folder, t, q, *, storage="mcap", topic="/joint_states", latency_ns=None, drop=None, empty=False):
    """A rosbag2 folder with JointState messages of ``q`` stamped ``EPOCH_NS + t`` (header, to the ns) and
    logged ``latency_ns[k]`` later; ``drop``: a message index left out.  Returns the folder."""
    rosbags = pytest.importorskip("rosbags")  # noqa: F841
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    plugin = {"mcap": StoragePlugin.MCAP, "db3": StoragePlugin.SQLITE3}[storage]
    with Writer(folder, version=9, storage_plugin=plugin) as w:
        conn = w.add_connection(topic, JointState.__msgtype__, typestore=store)
        w.add_connection("/rosout_counts", "std_msgs/msg/String", typestore=store)
        if empty:
            return folder
        for k in range(len(t)):
            if k == drop:
                continue
            ns = EPOCH_NS + round(t[k] * 1e9)
            names = ORDERS[k % 2]
            value = {"left_motor": q[k, 0], "right_motor": q[k, 1], "tool_roll": 0.25}
            msg = JointState(header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="base"),
                             name=list(names), position=np.array([value[j] for j in names]),
                             velocity=np.array([], dtype=float), effort=np.array([], dtype=float))
            log = ns + (0 if latency_ns is None else int(latency_ns[k]))
            w.write(conn, log, store.serialize_cdr(msg, JointState.__msgtype__))
    return folder


def _storage_file(folder):
    return next(p for p in folder.iterdir() if p.suffix in (".mcap", ".db3"))


@pytest.fixture(scope="module")
def bags(crossing, tmp_path_factory):
    """The crossing as an .mcap file, a .db3 file and a bag's folder (holding an .mcap)."""
    root = tmp_path_factory.mktemp("bags")
    mcap = _write_bag(root / "run_mcap", *crossing, storage="mcap")
    db3 = _write_bag(root / "run_db3", *crossing, storage="db3")
    return {"mcap": _storage_file(mcap), "db3": _storage_file(db3), "folder": mcap}


@pytest.mark.parametrize("kind", ["mcap", "db3", "folder"])
def test_a_bag_gets_the_verdict_of_the_same_readings_as_csv(bags, csv_verdict, capsys, kind):
    out = _verdict(capsys, bags[kind], "--joints", JOINTS)
    assert out == csv_verdict
    assert out["verdict"] == "mode-changed"


def test_monitor_reads_a_bag(bags, csv_verdict, capsys):
    code = main(["monitor", str(bags["mcap"]), "--joints", JOINTS, "--initial-mode", "1", "--json",
                 "--reasoning", "forward"])
    *events, summary = [json.loads(v) for v in capsys.readouterr().out.splitlines()]
    assert code == 0 and summary["interrupted"] is False
    assert summary["verdict"] == csv_verdict["verdict"] and summary["t_s"] == 0.001
    assert summary["steps"] == csv_verdict["steps"]
    # an event's position is the message's number on the topic (from 1)
    assert events and all(e["line"] == e["k"] + 1 for e in events)


def test_log_times_with_jitter_need_a_stamp_error(crossing, tmp_path, capsys):
    """The bag's receive times come 50-90 us after the header stamps: refused with a stamp error of 0 (a
    fixed-period controller), naming --stamp-error and --stamp header; read with a stamp error that bounds the
    latency, and the header stamps of the same bag are even."""
    t, q = crossing
    latency = np.random.default_rng(7).integers(50_000, 90_000, size=len(t))
    assert latency[0] != latency[1]
    bag = _storage_file(_write_bag(tmp_path / "jitter", t, q, latency_ns=latency))
    assert main(["check", str(bag), "--joints", JOINTS, "--stamp", "log", *FLAGS]) == 2
    err = _one_line_error(capsys)
    assert f"{bag}, message 2: the step" in err and "is not a whole number of periods" in err, err
    assert "--stamp-error" in err and "--stamp header" in err and "resample or" not in err
    out = _verdict(capsys, bag, "--joints", JOINTS, "--stamp", "log", "--stamp-error", "9e-5")
    assert out["verdict"] == "mode-changed"
    assert _verdict(capsys, bag, "--joints", JOINTS, "--stamp", "header")["verdict"] == "mode-changed"


def test_a_dropped_message_is_a_step_of_two_periods(crossing, tmp_path, capsys, csv_verdict):
    bag = _storage_file(_write_bag(tmp_path / "drop", *crossing, storage="db3", drop=100))
    out = _verdict(capsys, bag, "--joints", JOINTS)
    assert out["verdict"] == csv_verdict["verdict"] == "mode-changed"
    assert out["steps"] == csv_verdict["steps"] - 1


@pytest.mark.parametrize("args, message", [
    (["--topic", "/joint_state"], "no topic /joint_state in the bag; its topics: /joint_states "
                                  "(sensor_msgs/msg/JointState, {K} messages); /rosout_counts (std_msgs/msg/String, "
                                  "0 messages): name one with --topic"),
    (["--topic", "/rosout_counts"], "topic /rosout_counts carries std_msgs/msg/String, not sensor_msgs/msg/JointState"),
    ([], "the messages on /joint_states name the joints right_motor, tool_roll, left_motor: say which are q1..q2, "
         "in order, with --joints NAME,NAME"),
    (["--joints", "left_motor,elbow"], "message 1: no joint named elbow in the message (it names right_motor, tool_roll, "
                                       "left_motor); --joints names q1..q2"),
    (["--joints", "left_motor"], "--joints 'left_motor': give the 2 names of q1..q2"),
])
def test_bag_mistakes_are_one_line(bags, crossing, capsys, args, message):
    assert main(["check", str(bags["mcap"]), *args, *FLAGS]) == 2
    err = _one_line_error(capsys)
    assert message.replace("{K}", str(len(crossing[0]))) in err, err


@pytest.mark.parametrize("storage", ["mcap", "db3"])
def test_an_empty_bag_is_one_line(crossing, tmp_path, capsys, storage):
    bag = _storage_file(_write_bag(tmp_path / "empty", *crossing, storage=storage, empty=True))
    assert main(["check", str(bag), "--joints", JOINTS, *FLAGS]) == 2
    assert f"{bag}: empty bag: no message on /joint_states" in _one_line_error(capsys)


def test_a_file_that_is_no_bag_is_one_line(tmp_path, capsys):
    pytest.importorskip("rosbags")
    bag = tmp_path / "notes.mcap"
    bag.write_text("t,q1,q2\n")
    assert main(["check", str(bag), "--joints", JOINTS, *FLAGS]) == 2
    assert f"{bag}: cannot read as a ROS 2 bag (" in _one_line_error(capsys)


def test_without_the_extra_a_bag_names_it(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "rosbags", None)  # import rosbags fails, as when it is not installed
    for command in ("check", "monitor"):
        assert main([command, str(tmp_path / "run.mcap"), "--joints", JOINTS, "--initial-mode", "1"]) == 2
        err = _one_line_error(capsys)
        assert "reading ROS 2 bags needs the rosbags package: pip install 'crosscert[bags]'" in err, err


def test_bag_options_are_refused_for_a_csv(tmp_path, capsys):
    path = tmp_path / "run.csv"
    path.write_text("t,q1,q2\n0,1,1\n0.001,1,1\n")
    assert main(["check", str(path), "--topic", "/joint_states", *FLAGS]) == 2
    assert "--topic read ROS 2 bags (.mcap, .db3 or a bag's folder); " in _one_line_error(capsys)


def test_npz_gets_the_verdict_of_the_same_readings_as_csv(crossing, csv_verdict, tmp_path, capsys):
    t, q = crossing
    path = tmp_path / "run.npz"
    np.savez(path, t=t, q=q, note=np.array([1, 2, 3]))  # other arrays are not read
    assert _verdict(capsys, path) == csv_verdict


@pytest.mark.parametrize("arrays, message", [
    ({"time": np.arange(3.0), "q": np.ones((3, 2))}, "no array t; expected t (K,) in s and q (K, 2) (arrays: time, q)"),
    ({"t": np.arange(3.0), "q": np.ones((2, 3))}, "t has shape (3,) and q (2, 3); expected (K,) and (K, 2)"),
    ({"t": np.array([0.0, np.nan, 0.002]), "q": np.ones((3, 2))}, "index 1: t is not finite"),
    ({"t": np.array([0.0, 0.001, 0.0025]), "q": np.ones((3, 2))}, "index 2: the step 0.0015 s is not a whole number"),
])
def test_npz_mistakes_are_one_line(tmp_path, capsys, arrays, message):
    path = tmp_path / "run.npz"
    np.savez(path, **arrays)
    assert main(["check", str(path), *FLAGS]) == 2
    assert message in _one_line_error(capsys)


def test_an_object_array_is_not_unpickled(tmp_path):
    path = tmp_path / "run.npz"
    np.savez(path, t=np.array([0.0, 0.001], dtype=object), q=np.ones((2, 2)))
    with pytest.raises(TrajectoryFileError, match="cannot read as .npz"):
        NpzReader(path, 2)


def test_bag_options_are_refused_by_the_api_for_npz(tmp_path):
    path = tmp_path / "run.npz"
    np.savez(path, t=np.arange(2.0), q=np.ones((2, 2)))
    with pytest.raises(TrajectoryFileError, match="topic apply to ROS 2 bags"):
        with open_recording(path, 2, topic="/joint_states"):
            pass


#: The jittered bag: true sample times within JITTER of k t_s, header stamps within DELTA of them (1 ns
#: kept for the stamps' rounding to ns), message DROPPED left out.
JITTER, DELTA, DROPPED = 100e-6, 50e-6, 60


@pytest.fixture(scope="module")
def jittered_bag(tmp_path_factory):
    """An adversarial crossing (:mod:`adversarial`) sampled every period (a CSV) and at jittered times (a bag
    with one message dropped): ``(csv, bag, scenario at the jittered times, true sample of each message)``."""
    ts = DEXTAR.t_s
    even = near_scenarios(1, 11)[0]
    K = len(even.t)
    rng = np.random.default_rng(21)
    t_true = np.arange(K) * ts + rng.uniform(-JITTER, JITTER, K)
    t_true[0], t_true[-1] = 0.0, even.t[-1]  # the same span: the generator draws the same motion
    sc = near_scenarios(1, 11, times=t_true)[0]
    np.testing.assert_array_equal(sc.x[[0, -1]], even.x[[0, -1]])
    stamps = t_true + (DELTA - 1e-9) * np.where(np.arange(K) % 2 == 0, 1.0, -1.0)
    root = tmp_path_factory.mktemp("jittered")
    csv = root / "even.csv"
    write_trajectory(csv, even.t, even.q_meas)
    bag = _storage_file(_write_bag(root / "bag", stamps, sc.q_meas, drop=DROPPED))
    return csv, bag, sc, np.setdiff1d(np.arange(K), [DROPPED])


def test_a_jittered_bag_with_a_dropped_message_gets_the_csv_verdict(jittered_bag, capsys):
    csv, bag, sc, _ = jittered_bag
    mode = str(int(sc.mode[0]))
    flags = ["--initial-mode", mode, "--json", "--no-progress"]
    assert main(["check", str(csv), *flags]) == 0
    even = json.loads(capsys.readouterr().out)
    assert main(["check", str(bag), "--joints", JOINTS, "--stamp-error", str(DELTA), *flags]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["verdict"] == even["verdict"] == "mode-changed"
    assert out["steps"] == even["steps"] - 1
    # the stamps taken as exact (a fixed period): refused, with what to state
    assert main(["check", str(bag), "--joints", JOINTS, *flags]) == 2
    assert "--stamp-error" in _one_line_error(capsys)


def test_a_jittered_bag_keeps_the_truth_in_every_box(jittered_bag):
    """The boxes of the tracker and of the online monitor (its windows' re-seeded trackers) on the bag's
    readings and stamps, against the true pose and velocity at each message's true time."""
    _, bag, sc, true_k = jittered_bag
    model = interval_model()
    settings = TrackerSettings.for_robot(DEXTAR)
    with open_recording(bag, 2, joints=JOINTS.split(","), stamp_error=DELTA, nominal_t_s=DEXTAR.t_s) as reader:
        samples = list(reader.samples())
        clock = reader.clock
    q = np.array([s[2] for s in samples])
    assert len(q) == len(true_k) and not clock.even
    x0 = initial_box_from_mode(model, q[0], int(sc.mode[0]), settings)
    tracker = Tracker(model, settings, x0, clock=type(clock)(DEXTAR.t_s, DELTA))
    rows = [tracker.update(qk, float(s[1])) for qk, s in zip(q, samples)]
    boxes = {"x_lo": [r.x[0] for r in rows], "x_hi": [r.x[1] for r in rows], "xd_lo": [r.xd[0] for r in rows],
             "xd_hi": [r.xd[1] for r in rows]}
    for what, got in (("tracker", boxes), ("online", online_boxes(model, q, settings, x0, clock=clock))):
        for key, truth in (("x", sc.x[true_k]), ("xd", sc.xd[true_k])):
            lo, hi = np.asarray(got[f"{key}_lo"]), np.asarray(got[f"{key}_hi"])
            bad = np.flatnonzero(~np.all((lo <= truth) & (truth <= hi), axis=1))
            assert bad.size == 0, f"{what}: {key} outside its box at messages {bad[:5]}"
