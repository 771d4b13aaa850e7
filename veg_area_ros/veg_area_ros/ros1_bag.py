"""A ROS 1 bag (`rosbag record`'s `.bag`) read as a rosbag2 one: its connections, and each message converted to
ROS 2's CDR as `rosbags-convert` converts it (a header without `seq`, CameraInfo's `D K R P` as `d k r p`), so
everything that reads bags (measure, vogel, calibrate, play) takes a lab's older recordings as they are."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

from rosbags.convert.converter import migrate_message
from rosbags.rosbag1 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore


class Ros1Bag:
    """The rosbag2 Reader's interface (`connections`, `messages`, `close`) over a ROS 1 bag; messages come as
    ROS 2 CDR bytes of the same type, for the `target` type store."""

    def __init__(self, path: str | Path, target: Typestore) -> None:
        self._reader = Reader(Path(path))
        self._reader.open()
        self.connections = self._reader.connections
        self._source = get_typestore(Stores.ROS1_NOETIC)
        for connection in self.connections:  # a type Noetic lacks, as the bag defines it
            if connection.msgtype not in self._source.types and connection.msgdef.data:
                try:
                    self._source.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
                except Exception:  # a definition rosbags cannot parse: that topic alone stays undecodable
                    continue
        self._target = target
        self._cache: dict[str, object] = {}

    def messages(self, connections: Sequence = ()) -> Iterator[tuple[object, int, bytes]]:
        for connection, timestamp, raw in self._reader.messages(connections=connections):
            message = self._source.deserialize_ros1(raw, connection.msgtype)
            converted = migrate_message(self._source, self._target, connection.msgtype, connection.msgtype,
                                        self._cache, message)
            yield connection, timestamp, bytes(self._target.serialize_cdr(converted, connection.msgtype))

    def close(self) -> None:
        self._reader.close()
