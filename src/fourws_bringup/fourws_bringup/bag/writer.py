"""Write a rosbag2-layout MCAP bag chunk by chunk: :class:`BagWriter`, the recorder's storage.

A message's ``log_time`` is when the recorder received it on its node clock (simulated time
under ``use_sim_time``, so ``ros2 bag play`` paces a lockstep run at the simulated rate, as
rosbag2 does); its ``publish_time`` what the caller passes (the recorder: the publisher's
send time), else the header stamp (or a ``builtin_interfaces/Time`` first field, as in
``/clock``) read straight from the CDR bytes, else the log time; its ``sequence`` what the
caller passes (the recorder: the publisher's sequence number), else the count of the
topic's messages. Schemas carry the full ``ros2msg`` text and channels ``offered_qos_profiles`` and
``topic_type_hash`` (:mod:`.schema`, :mod:`.metadata`; docs/bags.md, "Layout").
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Iterable, Mapping
from pathlib import Path

import yaml

from fourws_common.topics import TopicInfo

from .errors import BagError
from .metadata import TopicRecord, build_metadata, qos_yaml, write_metadata
from .schema import cdr_stamp_ns, first_field_is_stamp, message_definition, type_hash


def compression_type(name: str):
    """mcap's ``CompressionType`` of a chunk compression name (zstd, lz4, none)."""
    from mcap.writer import CompressionType

    table = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
             "none": CompressionType.NONE, "": CompressionType.NONE}
    if name not in table:
        raise ValueError(f"compression: '{name}' is not one of zstd, lz4, none")
    return table[name]


class BagWriter:
    """Write serialized messages into a rosbag2-layout MCAP bag, chunk by chunk.

    ``folder`` must not exist or be empty. ``metadata.yaml`` is written at once (zero
    counts, ``custom_data.fourws_state: recording``), again after every completed chunk (the
    counts that are on disk), and finally by :meth:`close` (``complete``). After every
    completed chunk the file is flushed to the OS, so a killed process loses at most the
    chunk that was open. A chunk is completed when it holds ``chunk_size_bytes`` or, with
    ``chunk_max_span_ns``, once its messages span that much log time, whichever comes first:
    the loss is bounded in time as well as in bytes. :meth:`close` is idempotent.
    """

    def __init__(self, folder: str | Path, topics: Iterable[TopicInfo], *,
                 chunk_size_bytes: int = 262144, compression: str = "zstd",
                 chunk_max_span_ns: int | None = None,
                 library: str = "fourws recorder",
                 custom_data: Mapping[str, str] | None = None) -> None:
        from mcap.writer import LIBRARY_IDENTIFIER, Writer

        self.folder = Path(folder)
        if self.folder.exists() and (not self.folder.is_dir() or any(self.folder.iterdir())):
            raise ValueError(f"output_dir: {self.folder} exists and is not an empty folder")
        self.folder.mkdir(parents=True, exist_ok=True)
        self.file_name = f"{self.folder.name}_0.mcap"
        self.path = self.folder / self.file_name
        self._fh = open(self.path, "xb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._fh, chunk_size=int(chunk_size_bytes),
                              compression=compression_type(compression))
        self._writer.start(profile="ros2", library=f"{library}; {LIBRARY_IDENTIFIER}")
        self.compression = compression
        self.custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        self.records: dict[str, TopicRecord] = {}
        self._channels: dict[str, int] = {}
        self._stamped: dict[str, bool] = {}
        self._schemas: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        self._first_ns: int | None = None
        self._last_ns = 0
        self._durable: tuple[dict[str, int], int | None, int] = ({}, None, 0)
        self._pos = self._fh.tell()
        self._chunk_span_ns = chunk_max_span_ns
        self._chunk_first_ns: int | None = None   # log time of the open chunk's first message
        self.closed = False
        self.chunks_written = 0
        for t in topics:
            self.add_topic(t)
        self._write_metadata(durable=True, state="recording")

    def add_topic(self, info: TopicInfo) -> None:
        """Register a topic (schema once per type, one channel per topic)."""
        if info.name in self._channels:
            return
        definition = message_definition(info.type)
        if info.type not in self._schemas:
            self._schemas[info.type] = self._writer.register_schema(
                name=info.type, encoding="ros2msg", data=definition.encode("utf-8"))
        digest = type_hash(info.type, definition)
        meta = {"offered_qos_profiles": qos_yaml(info.qos)}
        if digest:
            meta["topic_type_hash"] = digest
        self._channels[info.name] = self._writer.register_channel(
            topic=info.name, message_encoding="cdr", schema_id=self._schemas[info.type],
            metadata=meta)
        self._stamped[info.name] = first_field_is_stamp(definition)
        self.records[info.name] = TopicRecord(info, 0, digest)
        self._seq[info.name] = 0

    def stamped(self, topic: str) -> bool:
        """Whether the topic's messages start with a stamp (used for publish_time)."""
        return self._stamped[topic]

    def write(self, topic: str, data: bytes, log_time_ns: int,
              publish_time_ns: int | None = None, sequence: int | None = None) -> bool:
        """Append one serialized message. Returns True when a chunk was completed (and flushed).

        ``publish_time_ns`` defaults to the message's stamp if it has one, else ``log_time_ns``;
        ``sequence`` to the count of the topic's messages written.
        """
        if self.closed:
            raise BagError(f"{self.path}: write after close")
        if publish_time_ns is None:
            stamp = cdr_stamp_ns(data) if self._stamped[topic] else None
            publish_time_ns = log_time_ns if stamp is None or stamp < 0 else stamp
        self._seq[topic] += 1
        seq = self._seq[topic] if sequence is None else int(sequence)
        self._writer.add_message(channel_id=self._channels[topic], log_time=int(log_time_ns),
                                 data=bytes(data), publish_time=int(publish_time_ns),
                                 sequence=seq & 0xFFFFFFFF)
        self.records[topic].message_count += 1
        self._first_ns = log_time_ns if self._first_ns is None else min(self._first_ns,
                                                                         log_time_ns)
        self._last_ns = max(self._last_ns, log_time_ns)
        if self._chunk_first_ns is None:
            self._chunk_first_ns = int(log_time_ns)
        pos = self._fh.tell()
        if (pos == self._pos and self._chunk_span_ns is not None
                and log_time_ns - self._chunk_first_ns >= self._chunk_span_ns):
            self._writer.flush()              # the open chunk spans the limit: complete it
            pos = self._fh.tell()
        if pos == self._pos:
            return False
        self._pos = pos
        self._chunk_first_ns = None
        self._fh.flush()
        self.chunks_written += 1
        self._durable = ({k: r.message_count for k, r in self.records.items()},
                         self._first_ns, self._last_ns)
        self._write_metadata(durable=True, state="recording")
        return True

    @property
    def message_count(self) -> int:
        return sum(r.message_count for r in self.records.values())

    def _write_metadata(self, *, durable: bool, state: str) -> None:
        if durable:
            counts, first, last = self._durable
        else:
            counts = {k: r.message_count for k, r in self.records.items()}
            first, last = self._first_ns, self._last_ns
        topics = [dataclasses.replace(r, message_count=counts.get(k, 0))
                  for k, r in self.records.items()]
        write_metadata(self.folder, relative_file_paths=[self.file_name], topics=topics,
                       starting_time_ns=first or 0,
                       duration_ns=(last - first) if first is not None else 0,
                       custom_data=self._custom(state))

    def _custom(self, state: str) -> dict[str, str]:
        """custom_data of metadata.yaml, and of its copy inside the MCAP (the same)."""
        return {**self.custom_data, "fourws_state": state,
                "fourws_chunk_compression": self.compression}

    def abandon(self) -> None:
        """Stop after a write error (a full disk): close the file as it is, every completed
        chunk in it, without a summary; metadata.yaml keeps the counts of those chunks (if it
        can be written at all). ``fourws bag recover`` restores the bag up to the failure."""
        self.closed = True            # also after a close() that failed half-way
        if not self._fh.closed:
            with contextlib.suppress(OSError):
                self._fh.close()
        with contextlib.suppress(OSError):
            self._write_metadata(durable=True, state="write failed")

    def close(self) -> None:
        """Finish the MCAP file (last chunk, summary, footer) and write final metadata.yaml."""
        if self.closed:
            return
        self.closed = True
        counts = {k: r.message_count for k, r in self.records.items()}
        first, last = self._first_ns, self._last_ns
        topics = [dataclasses.replace(r, message_count=counts[k]) for k, r in self.records.items()]
        info = build_metadata(relative_file_paths=[self.file_name], topics=topics,
                              starting_time_ns=first or 0,
                              duration_ns=(last - first) if first is not None else 0,
                              custom_data=self._custom("complete"))
        self._writer.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(
            info, sort_keys=False, default_flow_style=False)})
        self._writer.finish()
        self._fh.flush()
        with contextlib.suppress(OSError):
            os.fsync(self._fh.fileno())
        self._fh.close()
        self._write_metadata(durable=False, state="complete")
