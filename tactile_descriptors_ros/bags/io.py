"""Write and read rosbag2 bags (mcap or sqlite3) with rosbags, no rclpy needed.

Bags are written as rosbag2 metadata version 8 by default: the newest
version that Humble's ``ros2 bag`` still parses (version 9 stores
``offered_qos_profiles`` as a YAML list, which Humble rejects with "bad
conversion"), and one that Jazzy and Kilted read.  Each topic carries its
type's RIHS01 hash (``type_description_hash``, the same hash rosidl puts in
``<pkg>/msg/<Name>.json`` and rclpy reports for live endpoints), the full
``.msg`` definition (with comments, so units travel with the bag) and the
QoS profiles offered by its publishers.

Reading checks every known type's hash against the bag: a bag recorded with
another definition of a message is decoded with the definition stored in the
bag, or refused with :class:`~tactile_descriptors_ros.errors.BagError` when
the bag has none, never decoded with the wrong layout.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

from rosbags.interfaces import Connection, ConnectionExtRosbag2, Qos
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import StoragePlugin
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from ..errors import BagError
from .types import MSG_PACKAGE, ensure_types, full_msgtype, msg_dir, msgtype_of, tactile_typestore

__all__ = [
    "STORAGES",
    "BagMessage",
    "TopicInfo",
    "BagInfo",
    "BagWriter",
    "BagReader",
    "bag_info",
    "read_messages",
    "write_messages",
    "msgdef_text",
]

#: Storage plugins by the names ``ros2 bag`` uses.
STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


@dataclass(frozen=True)
class BagMessage:
    """One serialized message of a bag.

    Attributes
    ----------
    topic : str
    msgtype : str
        Full type name, ``pkg/msg/Name``.
    log_time_ns : int
        Time the message was recorded (rosbag2's ``timestamp``), ns.
    data : bytes
        CDR bytes exactly as published.
    """

    topic: str
    msgtype: str
    log_time_ns: int
    data: bytes


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: type, hash, message count and the QoS its publishers offered."""

    name: str
    msgtype: str
    type_hash: str
    message_count: int
    offered_qos: tuple[Qos, ...] = ()
    msgdef: str = ""


@dataclass(frozen=True)
class BagInfo:
    """What ``ros2 bag info`` shows."""

    path: str
    storage: str
    version: int
    start_ns: int
    end_ns: int
    message_count: int
    topics: dict[str, TopicInfo] = field(default_factory=dict)
    custom_data: dict[str, str] = field(default_factory=dict)
    ros_distro: str = ""

    @property
    def duration_ns(self) -> int:
        return max(0, self.end_ns - self.start_ns)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly form (QoS profiles as dicts)."""
        from .qos import qos_to_dict

        return {
            "path": self.path,
            "storage": self.storage,
            "version": self.version,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "duration_s": self.duration_ns / 1e9,
            "message_count": self.message_count,
            "ros_distro": self.ros_distro,
            "custom_data": dict(self.custom_data),
            "topics": {
                name: {
                    "type": t.msgtype,
                    "type_hash": t.type_hash,
                    "message_count": t.message_count,
                    "offered_qos_profiles": [qos_to_dict(q) for q in t.offered_qos],
                }
                for name, t in self.topics.items()
            },
        }


def msgdef_text(store: Typestore, msgtype: str) -> str:
    """The ``ros2msg`` definition rosbag2 stores for ``msgtype``: main text, then ``MSG:`` sections.

    For the project's own types the main section is the ``.msg`` file as
    written (comments and units included); dependencies come from the store.
    """
    msgtype = full_msgtype(msgtype)
    generated, _ = store.generate_msgdef(msgtype, ros_version=2)
    pkg, _, name = msgtype.split("/")
    if pkg != MSG_PACKAGE:
        return generated
    path = msg_dir() / f"{name}.msg"
    if not path.is_file():
        return generated
    text = path.read_text()
    from rosbags.typesys import get_types_from_msg

    parsed = get_types_from_msg(text, msgtype)[msgtype]
    if [(f[0], f[1]) for f in parsed[1]] != [(f[0], f[1]) for f in store.fielddefs[msgtype][1]]:
        return generated  # the store holds another definition (e.g. copied from an older bag)
    separator = "=" * 80 + "\n"
    _main, sep, deps = generated.partition(separator)
    if not text.endswith("\n"):
        text += "\n"
    return text + (sep + deps if sep else "")


class BagWriter:
    """Write a rosbag2 bag; use as a context manager.

    Parameters
    ----------
    path : str or path
        Bag directory to create; must not exist.
    storage : {"mcap", "sqlite3"}
    typestore : Typestore, optional
        Defaults to :func:`~tactile_descriptors_ros.bags.types.tactile_typestore`.
        Types it does not know are looked up in the installed ``.msg`` files.
    version : {8, 9}
        rosbag2 metadata version (8 is readable from Humble to Kilted).
    custom_data : dict of str to str, optional
        Stored in ``metadata.yaml`` (``custom_data``).

    Examples
    --------
    >>> with BagWriter("out_bag", storage="mcap") as bag:          # doctest: +SKIP
    ...     bag.add_topic("/label", "tactile_descriptors_msgs/msg/Label")
    ...     bag.write("/label", t_ns, label_message_or_cdr_bytes)
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        storage: str = "mcap",
        typestore: Typestore | None = None,
        version: int = 8,
        custom_data: dict[str, str] | None = None,
    ) -> None:
        if storage not in STORAGES:
            raise BagError(f"unknown bag storage {storage!r} (known: {', '.join(STORAGES)})")
        if version not in (8, 9):
            raise BagError(f"rosbag2 metadata version must be 8 or 9, not {version}")
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"{self.path} exists already; bags are never overwritten")
        self.storage = storage
        self.store = typestore or tactile_typestore()
        self._writer = Writer(self.path, version=version, storage_plugin=STORAGES[storage])  # type: ignore[arg-type]
        for key, value in (custom_data or {}).items():
            self._writer.set_custom_data(key, str(value))
        self._connections: dict[str, Connection] = {}
        self._open = False
        self._closed = False

    # ------------------------------------------------------------------ lifecycle
    def open(self) -> BagWriter:
        """Create the bag directory and storage file."""
        try:
            self._writer.open()
        except Exception as exc:  # rosbags WriterError, OSError
            raise BagError(f"cannot create bag {self.path}: {exc}") from exc
        self._open = True
        return self

    def close(self) -> None:
        """Finish the storage file and write ``metadata.yaml``; safe to call twice."""
        if self._open and not self._closed:
            self._closed = True
            try:
                self._writer.close()
            except Exception as exc:
                raise BagError(f"cannot finish bag {self.path}: {exc}") from exc

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        # Keep what was written even when the caller stopped on an error or Ctrl-C.
        self.close()

    def set_custom_data(self, key: str, value: str) -> None:
        """Add a ``custom_data`` entry to ``metadata.yaml`` (before :meth:`close`)."""
        self._writer.set_custom_data(key, str(value))

    # ------------------------------------------------------------------ topics
    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> message type of the topics added so far."""
        return {name: conn.msgtype for name, conn in self._connections.items()}

    def add_topic(
        self,
        topic: str,
        msgtype: str,
        offered_qos: Sequence[Qos] = (),
        msgdef: str | None = None,
    ) -> None:
        """Declare a topic (once; adding the same topic and type again is a no-op).

        Parameters
        ----------
        topic : str
        msgtype : str
            ``pkg/msg/Name`` (``pkg/Name`` is accepted).
        offered_qos : sequence of Qos
            QoS profiles of the topic's publishers, stored as ``offered_qos_profiles``.
        msgdef : str, optional
            The definition as found in another bag, for types not installed here.
        """
        if not self._open:
            raise BagError(f"bag {self.path} is not open")
        msgtype = full_msgtype(msgtype)
        if topic in self._connections:
            if self._connections[topic].msgtype != msgtype:
                raise BagError(
                    f"topic {topic} is already in the bag as {self._connections[topic].msgtype}, not {msgtype}"
                )
            return
        ensure_types(self.store, [msgtype], {msgtype: msgdef} if msgdef else None)
        try:
            conn = self._writer.add_connection(
                topic,
                msgtype,
                msgdef=msgdef_text(self.store, msgtype),
                rihs01=self.store.hash_rihs01(msgtype),
                offered_qos_profiles=list(offered_qos),
            )
        except Exception as exc:
            raise BagError(f"cannot add topic {topic} ({msgtype}) to {self.path}: {exc}") from exc
        self._connections[topic] = conn

    # ------------------------------------------------------------------ messages
    def serialize(self, message: Any, msgtype: str | None = None) -> bytes:
        """CDR bytes of a rosbags or rclpy message object."""
        msgtype = full_msgtype(msgtype) if msgtype else msgtype_of(message)
        if hasattr(message, "__msgtype__"):
            ensure_types(self.store, [msgtype])
            return bytes(self.store.serialize_cdr(message, msgtype))
        from rclpy.serialization import serialize_message

        return bytes(serialize_message(message))

    def write(self, topic: str, log_time_ns: int, message: bytes | bytearray | memoryview | Any) -> None:
        """Append one message (CDR bytes, or a message object to serialize).

        Raises
        ------
        BagError
            For an undeclared topic or a negative time.
        """
        conn = self._connections.get(topic)
        if conn is None:
            raise BagError(f"topic {topic} was not added to bag {self.path} (call add_topic first)")
        if log_time_ns < 0:
            raise BagError(f"negative log time {log_time_ns} ns for {topic}")
        if isinstance(message, (bytes, bytearray, memoryview)):
            data = bytes(message)
        else:
            data = self.serialize(message, conn.msgtype)
        self._writer.write(conn, int(log_time_ns), data)

    @property
    def message_count(self) -> int:
        return int(sum(self._writer.counts.values()))


def write_messages(
    path: str | os.PathLike[str],
    messages: Iterable[BagMessage],
    storage: str = "mcap",
    offered_qos: dict[str, Sequence[Qos]] | None = None,
    msgdefs: dict[str, str] | None = None,
) -> int:
    """Write ``messages`` (e.g. from :func:`read_messages`) to a new bag; returns the count."""
    offered_qos = offered_qos or {}
    msgdefs = msgdefs or {}
    n = 0
    with BagWriter(path, storage=storage) as bag:
        for msg in messages:
            if msg.topic not in bag.topics:
                bag.add_topic(msg.topic, msg.msgtype, offered_qos.get(msg.topic, ()), msgdefs.get(msg.msgtype))
            bag.write(msg.topic, msg.log_time_ns, msg.data)
            n += 1
    return n


class BagReader:
    """Read a rosbag2 bag (mcap or sqlite3, any metadata version up to 9).

    Parameters
    ----------
    path : str or path
        The bag directory (holding ``metadata.yaml``), or a single ``.mcap``
        or ``.db3`` storage file.
    typestore : Typestore, optional
        For :meth:`deserialize`; defaults to the tactile store.
    """

    def __init__(self, path: str | os.PathLike[str], typestore: Typestore | None = None) -> None:
        self.path = Path(path)
        if self.path.is_dir() and not (self.path / "metadata.yaml").is_file():
            raise BagError(f"{self.path}: not a rosbag2 bag (no metadata.yaml)")
        if not self.path.is_dir() and self.path.suffix not in (".mcap", ".db3"):
            raise BagError(f"{self.path}: not a bag directory, .mcap or .db3 file")
        if not self.path.exists():
            raise BagError(f"{self.path}: no such bag")
        self.store = typestore or tactile_typestore()
        try:
            self._reader = Reader(self.path)
        except Exception as exc:
            raise BagError(f"cannot read bag {self.path}: {exc}") from exc
        self._bag_stores: dict[str, Typestore] = {}
        self._checked: set[str] = set()
        self.info: BagInfo | None = None

    def open(self) -> BagReader:
        try:
            self._reader.open()
        except Exception as exc:
            raise BagError(f"cannot read bag {self.path}: {exc}") from exc
        r = self._reader
        topics = {}
        for conn in r.connections:
            ext = conn.ext
            qos = tuple(ext.offered_qos_profiles) if isinstance(ext, ConnectionExtRosbag2) else ()
            if conn.topic in topics:  # several connections of one topic (split bags): merge counts
                old = topics[conn.topic]
                topics[conn.topic] = TopicInfo(
                    old.name, old.msgtype, old.type_hash, old.message_count + conn.msgcount, old.offered_qos + qos,
                    old.msgdef,
                )
                continue
            topics[conn.topic] = TopicInfo(conn.topic, conn.msgtype, conn.digest or "", conn.msgcount, qos,
                                           conn.msgdef.data or "")
        meta = r.storage.metadata
        count = int(meta.message_count)
        storage = {".mcap": "mcap", ".db3": "sqlite3"}.get(self.path.suffix, "")
        version = 0
        if self.path.is_dir():
            import yaml

            raw = yaml.safe_load((self.path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
            storage = str(raw.get("storage_identifier", ""))
            version = int(raw.get("version", 0))
        self.info = BagInfo(
            path=str(self.path),
            storage=storage,
            version=version,
            start_ns=int(meta.start_time) if count else 0,
            end_ns=int(meta.end_time) - 1 if count else 0,
            message_count=count,
            topics=topics,
            custom_data=dict(meta.custom or {}),
            ros_distro=str(meta.ros_distro or ""),
        )
        return self

    def close(self) -> None:
        self._reader.close()

    def __enter__(self) -> BagReader:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def messages(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[BagMessage]:
        """Messages in log-time order, optionally of some topics and in ``[start_ns, stop_ns)``.

        Raises
        ------
        BagError
            If a requested topic is not in the bag.
        """
        conns = self._reader.connections
        if topics is not None:
            wanted = set(topics)
            known = {c.topic for c in conns}
            missing = wanted - known
            if missing:
                raise BagError(
                    f"{self.path}: no topic {', '.join(sorted(missing))} in the bag (has: {', '.join(sorted(known))})"
                )
            conns = [c for c in conns if c.topic in wanted]
        try:
            for conn, t_ns, data in self._reader.messages(connections=conns, start=start_ns, stop=stop_ns):
                yield BagMessage(conn.topic, conn.msgtype, int(t_ns), bytes(data))
        except BagError:
            raise
        except Exception as exc:
            raise BagError(f"{self.path}: cannot read messages: {exc}") from exc

    def _store_for(self, topic: str, msgtype: str) -> Typestore:
        """The store that decodes ``msgtype`` as recorded: ours if the hashes agree, else the bag's."""
        if topic in self._bag_stores:
            return self._bag_stores[topic]
        assert self.info is not None
        info = self.info.topics.get(topic)
        bag_hash = info.type_hash if info else ""
        bag_def = info.msgdef if info else ""
        store = self.store
        try:
            ensure_types(self.store, [msgtype], {msgtype: bag_def} if bag_def else None)
            ours = self.store.hash_rihs01(msgtype)
        except Exception as exc:  # noqa: BLE001 - unknown here, or conflicting with our definitions
            ours = ""
            if not bag_def:
                raise BagError(f"{self.path}: cannot decode {topic} ({msgtype}): {exc}") from exc
        if not ours or (bag_hash and bag_hash != ours):
            if not bag_def:
                raise BagError(
                    f"{self.path}: {topic} was recorded with another definition of {msgtype} "
                    f"(hash {bag_hash}, installed {ours}) and the bag does not store it: refusing to decode"
                )
            store = get_typestore(Stores.EMPTY)
            ensure_types(store, [msgtype], {msgtype: bag_def})
        self._bag_stores[topic] = store
        return store

    def deserialize(self, message: BagMessage) -> Any:
        """Decode a message into a rosbags message object (attribute access like rclpy's)."""
        store = self._store_for(message.topic, message.msgtype)
        try:
            return store.deserialize_cdr(message.data, message.msgtype)
        except Exception as exc:
            raise BagError(
                f"{self.path}: message on {message.topic} at {message.log_time_ns} ns does not decode "
                f"as {message.msgtype}: {exc}"
            ) from exc


def bag_info(path: str | os.PathLike[str]) -> BagInfo:
    """Summary of a bag (topics, types, hashes, counts, QoS, times)."""
    with BagReader(path) as reader:
        assert reader.info is not None
        return reader.info


def read_messages(
    path: str | os.PathLike[str], topics: Iterable[str] | None = None
) -> Iterator[BagMessage]:
    """All messages of a bag in log-time order (optionally of some topics)."""
    with BagReader(path) as reader:
        yield from reader.messages(topics)
