"""ROS 2 bags without ROS: read, check and write mcap / sqlite3 bags through rosbags.

- :func:`typestore` is the Jazzy type store with simreal_msgs registered, so bags we write are
  self-describing (rosbag2 format version 9 embeds every message definition).
- :class:`BagWriter` writes raw CDR (from rclpy ``raw=True`` subscriptions) or message objects.
- :func:`read_bag` yields messages in log-time order and fills a :class:`BagReport` with gaps,
  out-of-order stamps and undecodable messages instead of raising. A truncated mcap file (a
  recorder that was killed) is salvaged record by record up to the damage.
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from simreal_nodes.errors import BagError

if TYPE_CHECKING:
    from rosbags.interfaces import Connection

MSG_PACKAGES = ("simreal_msgs",)


def _msg_dirs(package: str) -> list[Path]:
    dirs = []
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        d = Path(prefix) / "share" / package / "msg"
        if d.is_dir():
            dirs.append(d)
    repo = Path(__file__).resolve().parents[2] / "simreal_msgs_py" / package / "msg"
    if repo.is_dir():
        dirs.append(repo)
    return dirs


def message_definitions(package: str = "simreal_msgs") -> dict[str, str]:
    """``{'pkg/msg/Name': definition text}`` for every .msg of a package (source of truth: the .msg files)."""
    for d in _msg_dirs(package):
        defs = {f"{package}/msg/{p.stem}": p.read_text() for p in sorted(d.glob("*.msg"))}
        if defs:
            return defs
    raise BagError(f"message definitions of '{package}' not found (looked in AMENT_PREFIX_PATH and the repository)")


@functools.lru_cache(maxsize=1)
def typestore():
    """The ROS 2 Jazzy type store with simreal's messages registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for pkg in MSG_PACKAGES:
        for name, text in message_definitions(pkg).items():
            types.update(get_types_from_msg(text, name))
    ts.register(types)
    return ts


def storage_plugin(name: str):
    from rosbags.rosbag2 import StoragePlugin

    try:
        return {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[name]
    except KeyError:
        raise BagError(f"bag storage '{name}' is not supported (expected 'mcap' or 'sqlite3')") from None


class BagWriter:
    """Write a rosbag2 bag (format 9: message definitions embedded).

    Use as a context manager; the bag is closed (and readable) on exit even when the body raises.
    """

    def __init__(self, path: str | Path, storage: str = "mcap"):
        from rosbags.rosbag2 import Writer

        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"output bag {self.path} already exists; choose a new name")
        self._ts = typestore()
        self._writer = Writer(self.path, version=9, storage_plugin=storage_plugin(storage))
        self._connections: dict[str, Connection] = {}
        self._types: dict[str, str] = {}
        self.count = 0
        self._open = False

    def open(self) -> BagWriter:
        self._writer.open()
        self._open = True
        return self

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._open:
            self._open = False
            self._writer.close()

    def add_topic(self, topic: str, msgtype: str) -> None:
        msgtype = normalize_type(msgtype)
        if topic in self._connections:
            if self._types[topic] != msgtype:
                raise BagError(f"topic {topic} already has type {self._types[topic]}, not {msgtype}")
            return
        if msgtype not in self._ts.types:
            raise BagError(f"message type {msgtype} is unknown to the type store; cannot record {topic}")
        self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=self._ts)
        self._types[topic] = msgtype

    def write_raw(self, topic: str, timestamp_ns: int, data: bytes, msgtype: str | None = None) -> None:
        """Write serialized CDR bytes (as rclpy raw subscriptions give them)."""
        if topic not in self._connections:
            if msgtype is None:
                raise BagError(f"topic {topic} was not added to the bag")
            self.add_topic(topic, msgtype)
        self._writer.write(self._connections[topic], int(timestamp_ns), bytes(data))
        self.count += 1

    def write(self, topic: str, timestamp_ns: int, msg, msgtype: str) -> None:
        """Serialize a rosbags message object and write it."""
        msgtype = normalize_type(msgtype)
        self.write_raw(topic, timestamp_ns, self._ts.serialize_cdr(msg, msgtype), msgtype)


def normalize_type(msgtype: str) -> str:
    """'sensor_msgs/Image' or 'sensor_msgs/msg/Image' -> 'sensor_msgs/msg/Image'."""
    parts = msgtype.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return msgtype


# ---------------------------------------------------------------------------------------------
# Reading


@dataclass
class BagMessage:
    topic: str
    msgtype: str
    log_time_ns: int
    raw: bytes


@dataclass
class BagReport:
    """What reading a bag found besides messages: counts and problems, never an exception."""

    path: str = ""
    counts: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    gaps: list[tuple[str, float, float]] = field(default_factory=list)  # topic, at_s, gap_s
    out_of_order: list[tuple[str, int, float]] = field(default_factory=list)  # topic, index, stamp_s
    undecodable: list[tuple[str, int, str]] = field(default_factory=list)  # topic, index, error
    salvaged: bool = False
    damage: str = ""

    @property
    def problems(self) -> int:
        return len(self.gaps) + len(self.out_of_order) + len(self.undecodable) + int(bool(self.damage))

    def summary(self) -> str:
        lines = [f"bag {self.path}: " + ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))]
        if self.damage:
            lines.append(f"  damaged: {self.damage}"
                         + (" (salvaged the messages before the damage)" if self.salvaged else ""))
        for t, at, gap in self.gaps[:20]:
            lines.append(f"  gap on {t}: {gap * 1e3:.1f} ms without messages at t={at:.3f} s")
        for t, i, s in self.out_of_order[:20]:
            lines.append(f"  out-of-order stamp on {t}: message {i} has stamp {s:.6f} s, earlier than the one before")
        for t, i, e in self.undecodable[:20]:
            lines.append(f"  undecodable message {i} on {t}: {e}")
        extra = (self.problems - min(20, len(self.gaps)) - min(20, len(self.out_of_order))
                 - min(20, len(self.undecodable)) - int(bool(self.damage)))
        if extra > 0:
            lines.append(f"  ... and {extra} more problems")
        return "\n".join(lines)


def _header_stamp_ns(ts, raw: bytes, msgtype: str) -> int | None:
    msg = ts.deserialize_cdr(raw, msgtype)
    hdr = getattr(msg, "header", None)
    if hdr is None:
        return None
    return int(hdr.stamp.sec) * 1_000_000_000 + int(hdr.stamp.nanosec)


def bag_topics(path: str | Path) -> dict[str, str]:
    """``{topic: msgtype}`` of a bag (raises BagError if it cannot be opened at all)."""
    out = {}
    for m in read_bag(path, BagReport(), check=False, decode_check=False, only_headers=True):
        out[m.topic] = m.msgtype
    return out


def read_bag(path: str | Path, report: BagReport | None = None, topics: Iterable[str] | None = None,
             check: bool = True, decode_check: bool = True, only_headers: bool = False) -> Iterator[BagMessage]:
    """Yield the messages of a rosbag2 bag (mcap or sqlite3) in log-time order.

    Problems go to ``report`` (gaps, out-of-order header stamps, undecodable messages, damage).
    A bag that cannot be opened at all raises :class:`BagError` with the reason.
    ``only_headers`` stops after the connection list (used by :func:`bag_topics`).
    """
    report = report if report is not None else BagReport()
    path = Path(path)
    report.path = str(path)
    if not path.exists():
        raise BagError(f"bag not found: {path}")
    wanted = set(topics) if topics is not None else None
    ts = typestore()
    last_log: dict[str, int] = {}
    periods: dict[str, list[int]] = defaultdict(list)
    last_stamp: dict[str, int] = {}
    index: dict[str, int] = defaultdict(int)

    def account(topic, msgtype, t, raw):
        i = index[topic]
        index[topic] += 1
        report.counts[topic] += 1
        if check:
            if topic in last_log:
                periods[topic].append(t - last_log[topic])
            last_log[topic] = t
        if decode_check:
            try:
                s = _header_stamp_ns(ts, raw, msgtype)
            except Exception as e:  # noqa: BLE001 - any decoder failure is a finding
                report.undecodable.append((topic, i, f"{type(e).__name__}: {e}"))
                return False
            if check and s is not None:
                if topic in last_stamp and s < last_stamp[topic]:
                    report.out_of_order.append((topic, i, s * 1e-9))
                last_stamp[topic] = s
        return True

    try:
        source = _iter_rosbags(path, wanted, only_headers)
        for topic, msgtype, t, raw in source:
            if only_headers:
                yield BagMessage(topic, msgtype, 0, b"")
                continue
            ok = account(topic, msgtype, t, raw)
            if ok:
                yield BagMessage(topic, msgtype, t, raw)
    except _Unreadable as e:
        mcaps = sorted(path.glob("*.mcap")) if path.is_dir() else ([path] if path.suffix == ".mcap" else [])
        if not mcaps:
            raise BagError(f"cannot read bag {path}: {e}") from None
        report.damage = str(e)
        report.salvaged = True
        for topic, msgtype, t, raw in _salvage_mcap(mcaps, wanted, report, only_headers):
            if only_headers:
                yield BagMessage(topic, msgtype, 0, b"")
                continue
            if account(topic, msgtype, t, raw):
                yield BagMessage(topic, msgtype, t, raw)
    if check:
        for topic, dts in periods.items():
            if len(dts) < 3:
                continue
            d = np.asarray(dts, dtype=np.float64)
            med = float(np.median(d[d > 0])) if np.any(d > 0) else 0.0
            if med <= 0:
                continue
            acc = 0
            for _k, dt in enumerate(dts):
                acc += dt
                if dt > 3.0 * med and dt > 5e7:
                    report.gaps.append((topic, acc * 1e-9, dt * 1e-9))


class _Unreadable(Exception):
    pass


def _iter_rosbags(path: Path, wanted, only_headers):
    from rosbags.highlevel import AnyReader

    try:
        reader = AnyReader([path], default_typestore=typestore())
        if path.is_dir() and not reader.is2:
            # rosbags takes any path ending in '.bag' for a ROS 1 bag file; a rosbag2 folder named so ('run.bag', as a
            # user names a recording) is a rosbag2 bag all the same
            from rosbags.rosbag2 import Reader as Reader2
            reader.is2, reader.readers = True, [Reader2(path)]
        reader.open()
    except Exception as e:  # noqa: BLE001
        raise _Unreadable(f"{type(e).__name__}: {e}") from None
    try:
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if only_headers:
            for c in conns:
                yield c.topic, c.msgtype, 0, b""
            return
        it = reader.messages(connections=conns) if conns else iter(())
        while True:
            try:
                con, t, raw = next(it)
            except StopIteration:
                return
            except Exception as e:  # noqa: BLE001 - damage in the middle of the file
                raise _Unreadable(f"{type(e).__name__}: {e}") from None
            yield con.topic, con.msgtype, int(t), bytes(raw)
    finally:
        with contextlib.suppress(Exception):
            reader.close()


def _salvage_mcap(files, wanted, report: BagReport, only_headers: bool):
    """Read an mcap file record by record until the damage (killed recorder, truncation)."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    for f in files:
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        with open(f, "rb") as fh:
            try:
                for rec in StreamReader(fh, skip_magic=False).records:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec.name
                    elif isinstance(rec, Channel):
                        channels[rec.id] = (rec.topic, schemas.get(rec.schema_id, ""))
                        if only_headers and (wanted is None or rec.topic in wanted):
                            yield rec.topic, channels[rec.id][1], 0, b""
                    elif isinstance(rec, Message) and not only_headers:
                        topic, msgtype = channels.get(rec.channel_id, ("", ""))
                        if not topic or (wanted is not None and topic not in wanted):
                            continue
                        yield topic, msgtype, int(rec.log_time), bytes(rec.data)
            except Exception as e:  # noqa: BLE001 - end of the good part
                report.damage += f"; salvage stopped at {type(e).__name__}: {e}"


def decode(msg: BagMessage):
    """Deserialize a :class:`BagMessage` into a rosbags message object."""
    return typestore().deserialize_cdr(msg.raw, msg.msgtype)


def stamp_ns(msg_obj) -> int:
    return int(msg_obj.header.stamp.sec) * 1_000_000_000 + int(msg_obj.header.stamp.nanosec)
