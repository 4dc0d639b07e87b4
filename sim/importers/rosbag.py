"""ROS 2 bags (``rosbags``; sqlite3 or mcap storage): the ``sensor_msgs/msg/JointState``
messages of one topic as columns ``time`` (the header stamp from the first message's, or the
bag's receive time where stamps are zero), ``position.k``, ``velocity.k``, ``effort.k``
(k = 1.. in the order of the first message's joint names)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import ReaderError
from rosbags.typesys import Stores, get_typestore

from serpar.sim.importers.tables import RawTable
from serpar.sim.recording import RecordingError

JOINT_STATE = "sensor_msgs/msg/JointState"
FIELDS = ("position", "velocity", "effort")


def _topic(reader: AnyReader, path: Path, topic: str | None):  # -> rosbags Connection
    joint = [c for c in reader.connections if c.msgtype == JOINT_STATE]
    listed = ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections) or "none"
    if topic is not None:
        chosen = [c for c in joint if c.topic == topic]
        if not chosen:
            raise RecordingError(f"{path}: no {JOINT_STATE} topic {topic!r}; its topics: {listed}")
        return chosen
    if not joint:
        raise RecordingError(f"{path}: no {JOINT_STATE} topic; its topics: {listed}")
    if len({c.topic for c in joint}) > 1:
        raise RecordingError(f"{path}: several {JOINT_STATE} topics "
                             f"({', '.join(sorted({c.topic for c in joint}))}); choose one with --topic")
    return joint


def read_rosbag(path: str | Path, topic: str | None = None) -> RawTable:
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path} does not exist")
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            connections = _topic(reader, path, topic)
            stamps, names, values = [], None, {f: [] for f in FIELDS}
            for n, (conn, received, raw) in enumerate(reader.messages(connections=connections), 1):
                msg = reader.deserialize(raw, conn.msgtype)
                stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
                stamps.append(stamp if stamp > 0 else 1e-9 * received)
                order = list(msg.name)
                if names is None:
                    names = order
                elif sorted(order) != sorted(names):
                    raise RecordingError(f"{path} message {n}: joints {order}, the first "
                                         f"message has {names}")
                index = [order.index(j) for j in names]
                for f in FIELDS:
                    v = np.asarray(getattr(msg, f), float)
                    values[f].append(v[index] if v.size == len(order) else np.full(len(names), np.nan))
    except ReaderError as exc:
        raise RecordingError(f"{path} is not a readable ROS 2 bag ({exc})") from None
    if not stamps:
        raise RecordingError(f"{path}: topic {connections[0].topic} holds no messages")
    t = np.asarray(stamps)
    columns = {"time": t - t[0]}
    notes = [(f"{path.name}: topic {connections[0].topic}, joints {', '.join(names or [])} "
             f"(columns .1..{len(names or [])} in this order); time from the first stamp, "
             f"{t[0]:.9f} s")]
    for f in FIELDS:
        block = np.array(values[f])
        if np.all(np.isnan(block)):
            notes.append(f"{path.name}: JointState.{f} is empty in every message")
            continue
        columns.update({f"{f}.{k + 1}": block[:, k] for k in range(block.shape[1])})
    return RawTable(str(path), columns, "message", 1, None, tuple(notes))
