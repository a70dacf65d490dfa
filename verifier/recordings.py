"""Recordings in every format ``crosscert check`` and ``monitor`` read, behind one reader.

:func:`open_recording` opens a trajectory CSV (:class:`~verifier.trajfile.TrajectoryReader`),
a ROS 2 bag (:class:`BagReader`: ``sensor_msgs/msg/JointState`` messages of a
``.mcap`` or ``.db3`` file, or of a bag's folder) or a ``.npz`` file of arrays
(:class:`NpzReader`), and yields a :class:`~verifier.trajfile.SampleReader`
whose ``samples()`` are ``(position, t, q)``: every format passes the same
checks of its times (strictly increasing, a constant step within
:func:`~verifier.trajfile.step_tolerance`), with the same messages.

Bags are read with the pure-Python ``rosbags`` package (the ``bags`` extra:
``pip install 'crosscert[bags]'``); no ROS installation is needed.
"""

from __future__ import annotations

import contextlib
import enum
import importlib
import zipfile
from pathlib import Path

import numpy as np

from crosscert.robots.errors import TrajectoryFileError

from .trajfile import SampleReader, TrajectoryReader, checked_path, open_trajectory

__all__ = ["open_recording", "recording_format", "RecordingFormat", "Stamp", "BagReader", "NpzReader",
           "require_rosbags", "DEFAULT_TOPIC", "JOINT_STATE", "BAG_SUFFIXES"]

#: The topic a bag's joints are read from unless another is named.
DEFAULT_TOPIC = "/joint_states"
#: The message type read from a bag.
JOINT_STATE = "sensor_msgs/msg/JointState"
#: Suffixes of the rosbag2 storage files read (MCAP, SQLite 3).
BAG_SUFFIXES = (".mcap", ".db3")
#: What the missing extra is called in messages.
BAGS_EXTRA = "pip install 'crosscert[bags]'"


class RecordingFormat(enum.Enum):
    """The format of a recording, from its name (:func:`recording_format`)."""

    CSV = "CSV"
    BAG = "ROS 2 bag"
    NPZ = ".npz"


class Stamp(str, enum.Enum):
    """Which time of a bag's message is the sample's time."""

    #: ``header.stamp``: when the publisher stamped the reading.
    HEADER = "header"
    #: The bag's log time: when the recorder received the message.
    LOG = "log"


def recording_format(path) -> RecordingFormat:
    """The format of the recording at ``path``: a bag by its suffix (``.mcap``, ``.db3``) or as a folder holding a
    ``metadata.yaml``, ``.npz`` by its suffix, CSV otherwise (``-``, a pipe, any other name)."""
    p = Path(str(path))
    if str(path) != "-" and (p.suffix in BAG_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").is_file())):
        return RecordingFormat.BAG
    if p.suffix == ".npz":
        return RecordingFormat.NPZ
    return RecordingFormat.CSV


def require_rosbags(name) -> None:
    """Import ``rosbags``, or say which extra installs it.

    Raises
    ------
    TrajectoryFileError
        Naming ``name`` and ``pip install 'crosscert[bags]'`` when rosbags cannot be imported.
    """
    try:
        importlib.import_module("rosbags")  # the package first: a stale submodule in sys.modules proves nothing
        importlib.import_module("rosbags.highlevel")
    except ImportError:
        raise TrajectoryFileError(f"{name}: reading ROS 2 bags needs the rosbags package: {BAGS_EXTRA}") from None


class BagReader(SampleReader):
    """The ``sensor_msgs/msg/JointState`` messages of one topic of a ROS 2 bag, as samples.

    Open it as a context manager (:func:`open_recording` does): the bag is
    opened, the topic found and its first message read, so that a wrong
    topic, an empty bag or joints the messages do not name fail before any
    sample is tracked.  Times are the messages' stamps (``stamp``), in s from
    the first message's, computed from integer nanoseconds (one rounding);
    ``q`` holds the ``position`` of the joints ``joints`` names, in that order,
    matched by name in each message (their order and any other joint in the
    message do not matter).  Positions are message numbers on the topic, from 1.

    Parameters
    ----------
    path : path
        A ``.mcap`` or ``.db3`` storage file, or a bag's folder (with ``metadata.yaml``).
    n : int
        Number of joints of the robot.
    topic : str
        The topic of the joint states.
    joints : sequence of str, optional
        The message's names of the joints ``q1 .. qn``; required (the error
        lists the names the messages carry).
    stamp : Stamp or str
        ``header`` (the publisher's stamp) or ``log`` (the bag's receive time).
    **checks
        ``t_s``, ``nominal_t_s``, ``q_range`` of :class:`~verifier.trajfile.SampleReader`.

    Raises
    ------
    TrajectoryFileError
        On opening: rosbags missing, not a bag, no such topic (the bag's topics
        are listed), not JointState, no message, joints not named; while
        iterating: a message without a joint, a non-finite position, and the
        time checks of :class:`~verifier.trajfile.SampleReader`.
    """

    where = "message"

    def __init__(self, path, n: int, *, topic: str = DEFAULT_TOPIC, joints=None, stamp: Stamp | str = Stamp.HEADER,
                 **checks):
        super().__init__(n, str(path), **checks)
        self.path, self.topic, self.stamp = Path(path), topic, Stamp(stamp)
        self.joints = None if joints is None else tuple(joints)
        self.restamp = ("write the bag's readings with the stamps t_k = t_0 + k t_s to a CSV or .npz file (readings "
                        "unchanged)")
        if self.stamp is Stamp.LOG:
            self.uneven_hint = ("; or read the publisher's stamps with --stamp header (--stamp log reads when the "
                                "recorder received each message)")
        self._stack = None
        self._errors = ()  # rosbags' read errors, once it is imported
        self._bag = None
        self._messages = None
        self._first = None
        self._t0_ns = None
        self._names = None
        self._index = None

    def _order_hint(self) -> str:
        if self.stamp is Stamp.HEADER:
            return (" (are the messages' header stamps filled in? --stamp log reads when the recorder received each "
                    "message)")
        return ""

    def _bag_error(self, exc) -> TrajectoryFileError:
        return TrajectoryFileError(f"{self.name}: cannot read as a ROS 2 bag ({exc})")

    def __enter__(self) -> BagReader:
        require_rosbags(self.name)
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore

        self._errors = (AnyReaderError, OSError, ValueError)
        with contextlib.ExitStack() as stack:
            try:
                # the bag's own message definitions are used; the typestore only for a bag that has none
                bag = stack.enter_context(AnyReader([self.path], default_typestore=get_typestore(Stores.LATEST)))
            except self._errors as exc:
                raise self._bag_error(exc) from None
            connections = self._connections(bag)
            self._bag, self._messages = bag, bag.messages(connections=connections)
            self._first = self._next()  # by reading, not by the count of a summary a cut recording may lack
            if self._first is None:
                raise TrajectoryFileError(f"{self.name}: empty bag: no message on {self.topic}")
            self._stack = stack.pop_all()
        return self

    def __exit__(self, *exc) -> None:
        if self._stack is not None:
            self._stack.close()
            self._stack = None

    def _connections(self, bag):
        """The connections of the topic, or an error that says what the bag holds."""
        topics = bag.topics
        if not topics:
            raise TrajectoryFileError(f"{self.name}: empty bag (no topic, no message)")
        if self.topic not in topics:
            listed = "; ".join(f"{name} ({info.msgtype}, {info.msgcount} messages)" for name, info in sorted(topics.items()))
            raise TrajectoryFileError(f"{self.name}: no topic {self.topic} in the bag; its topics: {listed}: name one "
                                      "with --topic")
        info = topics[self.topic]
        if info.msgtype != JOINT_STATE:
            raise TrajectoryFileError(f"{self.name}: topic {self.topic} carries {info.msgtype}, not {JOINT_STATE}")
        return info.connections

    def _next(self):
        """The next message's ``(number, t, q)``, or None at the end."""
        try:
            connection, log_ns, raw = next(self._messages)
            msg = self._bag.deserialize(raw, connection.msgtype)
        except StopIteration:
            return None
        except self._errors as exc:
            raise self._bag_error(exc) from None
        self.line += 1
        ns = log_ns if self.stamp is Stamp.LOG else int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
        if self._t0_ns is None:
            self._t0_ns = ns
        # a difference of integers is exact: one rounding to s, whatever the stamps' epoch
        return self.line, (ns - self._t0_ns) / 1e9, self._positions(msg)

    def _positions(self, msg):
        """The positions of ``joints`` in the message, matched by name (the mapping kept while the names repeat)."""
        names = tuple(msg.name)
        if names != self._names:
            listed = ", ".join(names) or "none"
            if self.joints is None:
                raise TrajectoryFileError(
                    f"{self.name}: the messages on {self.topic} name the joints {listed}: say which are "
                    f"q1..q{self.n}, in order, with --joints NAME,NAME (the robots declare no joint names)")
            missing = [j for j in self.joints if j not in names]
            if missing:
                raise self._error(f"no joint named {', '.join(missing)} in the message (it names {listed}); --joints names "
                                  f"q1..q{self.n}")
            twice = [j for j in self.joints if names.count(j) > 1]
            if twice:
                raise self._error(f"joint {', '.join(twice)} named twice in the message")
            self._names, self._index = names, [names.index(j) for j in self.joints]
        position = np.asarray(msg.position, dtype=float)
        if position.shape != (len(names),):
            raise self._error(f"{position.size} positions for {len(names)} joint names")
        q = position[self._index]
        bad = np.flatnonzero(~np.isfinite(q))
        if bad.size:
            raise self._error(f"the position of joint {self.joints[bad[0]]} is {q[bad[0]]} (NaN and infinities are "
                              "not allowed)")
        return q

    def _records(self):
        if self._first is None:
            raise TrajectoryFileError(f"{self.name}: open the bag first (with BagReader(...) as reader)")
        record = self._first
        while record is not None:
            yield (*record, None)
            record = self._next()


class NpzReader(SampleReader):
    """The arrays ``t`` (K,) s and ``q`` (K, n) of a ``.npz`` file (``numpy.savez``), as samples.

    Other arrays in the file are not read.  Nothing is unpickled
    (``allow_pickle=False``).  Positions are the samples' indices, from 0.

    Parameters
    ----------
    path : path
    n : int
        Number of joints of the robot.
    **checks
        ``t_s``, ``nominal_t_s``, ``q_range`` of :class:`~verifier.trajfile.SampleReader`.

    Raises
    ------
    TrajectoryFileError
        Not an ``.npz``, ``t`` or ``q`` missing, shapes other than (K,) and
        (K, n), values that are not finite numbers; and the time checks of
        :class:`~verifier.trajfile.SampleReader`.
    """

    where = "index"
    restamp = "write t again as t_k = t_0 + k t_s (q unchanged)"

    def __init__(self, path, n: int, **checks):
        super().__init__(n, str(path), **checks)
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = [k for k in ("t", "q") if k not in data.files]
                if missing:
                    raise TrajectoryFileError(f"{self.name}: no array {', '.join(missing)}; expected t (K,) in s and "
                                              f"q (K, {n}) (arrays: {', '.join(data.files) or 'none'})")
                t, q = data["t"], data["q"]
        except (OSError, ValueError, zipfile.BadZipFile) as exc:
            raise TrajectoryFileError(f"{self.name}: cannot read as .npz ({exc})") from None
        for key, a in (("t", t), ("q", q)):
            if a.dtype.kind not in "fiu":
                raise TrajectoryFileError(f"{self.name}: array {key} holds {a.dtype}, not numbers")
        if t.ndim != 1 or q.shape != (t.size, n):
            raise TrajectoryFileError(f"{self.name}: t has shape {t.shape} and q {q.shape}; expected (K,) and (K, {n})")
        self.t, self.q = t.astype(float), q.astype(float)
        for key, a in (("t", self.t), ("q", self.q)):
            bad = np.flatnonzero(~np.isfinite(a.reshape(t.size, -1)).all(axis=1))
            if bad.size:
                self.line = int(bad[0])
                raise self._error(f"{key} is not finite (NaN and infinities are not allowed)")

    def _records(self):
        for k in range(self.t.size):
            yield k, float(self.t[k]), self.q[k], None


@contextlib.contextmanager
def open_recording(path, n: int, *, topic: str | None = None, joints=None, stamp: Stamp | str | None = None, **checks):
    """The reader of the recording at ``path``, by its format (:func:`recording_format`); its ``samples()`` yield
    ``(position, t, q)``, checked.

    Parameters
    ----------
    path : path or ``-``
        A CSV (``-``: stdin; a named pipe is read as written), a ROS 2 bag, or a ``.npz``.
    n : int
        Number of joints of the robot.
    topic, joints, stamp
        For a bag (:class:`BagReader`; ``None``: :data:`DEFAULT_TOPIC`, ``header``); refused for another format.
    **checks
        ``t_s``, ``nominal_t_s``, ``q_range`` of :class:`~verifier.trajfile.SampleReader`.

    Raises
    ------
    TrajectoryFileError
        A missing path, bag options for a recording that is not a bag, and
        what the format's reader raises.
    """
    fmt = recording_format(path)
    given = [name for name, v in (("topic", topic), ("joints", joints), ("stamp", stamp)) if v is not None]
    if fmt is not RecordingFormat.BAG and given:
        raise TrajectoryFileError(f"{path}: {', '.join(given)} apply to ROS 2 bags ({', '.join(BAG_SUFFIXES)}), and "
                                  f"this recording is read as {fmt.value}")
    if fmt is RecordingFormat.CSV:
        with open_trajectory(path) as (fh, name):
            yield TrajectoryReader(fh, n, name, **checks)
    elif fmt is RecordingFormat.NPZ:
        yield NpzReader(checked_path(path), n, **checks)
    else:
        require_rosbags(path)
        with BagReader(checked_path(path, folder=True), n, topic=DEFAULT_TOPIC if topic is None else topic,
                       joints=joints, stamp=Stamp.HEADER if stamp is None else stamp, **checks) as reader:
            yield reader
