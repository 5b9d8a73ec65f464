"""Read a finished MCAP file of a bag: find it, check it is whole, list and iterate it.

:func:`resolve_mcap` finds the file of a run folder (``bag/`` inside), a bag folder
(``metadata.yaml``'s ``relative_file_paths``) or takes a bare ``.mcap``; :func:`check_mcap`
tells a whole file from a truncated one (magic at both ends, a footer record) before any
reader is asked; :class:`McapBag` lists the channels (:class:`ChannelInfo`: type, schema
text, offered QoS, count) and yields messages raw or decoded, in recorded order
(docs/bags.md, "Reading"). Every problem is a :class:`~.errors.BagError` naming the file.
"""

from __future__ import annotations

import contextlib
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from .errors import BagError
from .metadata import parse_offered_qos

MCAP_MAGIC = b"\x89MCAP0\r\n"
FOOTER_RECORD_LEN = 1 + 8 + 20  # opcode, length, summary_start, summary_offset_start, crc


def _size_text(n: int) -> str:
    if n >= 1_000_000:
        return f"{n / 1e6:.1f} MB"
    if n >= 1000:
        return f"{n / 1e3:.1f} kB"
    return f"{n} bytes"


def resolve_mcap(path: str | Path) -> Path:
    """The MCAP file of a run folder (``bag/`` inside), a bag folder or a bare ``.mcap``."""
    p = Path(path)
    if p.is_file():
        return p
    if not p.exists():
        raise BagError(f"{p}: no such bag, run folder or MCAP file")
    if (p / "bag").is_dir() and not (p / "metadata.yaml").is_file():
        p = p / "bag"
    meta = p / "metadata.yaml"
    if meta.is_file():
        try:
            info = (yaml.safe_load(meta.read_text(encoding="utf-8")) or {}).get(
                "rosbag2_bagfile_information", {})
            files = [p / Path(f).name for f in info.get("relative_file_paths", [])]
        except (yaml.YAMLError, AttributeError) as exc:
            raise BagError(f"{meta}: not a rosbag2 metadata file: {exc}") from exc
        files = [f for f in files if f.suffix == ".mcap"]
        if files:
            if not files[0].is_file():
                raise BagError(f"{meta}: lists {files[0].name}, which does not exist")
            return files[0]
    found = sorted(p.glob("*.mcap"))
    if not found:
        raise BagError(f"{p}: no .mcap file in this folder")
    return found[0]


def check_mcap(path: Path) -> None:
    """Raise :class:`BagError` unless the file starts and ends like a finished MCAP file."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(8)
            if size >= 8 + FOOTER_RECORD_LEN + 8:
                fh.seek(size - FOOTER_RECORD_LEN - 8)
                tail = fh.read(FOOTER_RECORD_LEN + 8)
            else:
                tail = b""
    except OSError as exc:
        raise BagError(f"{path}: cannot read: {exc.strerror}") from exc
    if size == 0:
        raise BagError(f"{path}: empty file (the recorder wrote nothing)")
    if head != MCAP_MAGIC:
        if len(head) < 8 and head == MCAP_MAGIC[:len(head)]:
            raise BagError(f"{path}: truncated after {_size_text(size)} (no MCAP header)")
        raise BagError(f"{path}: not an MCAP file (bad magic)")
    if not (tail.endswith(MCAP_MAGIC) and tail[0] == 0x02
            and struct.unpack_from("<Q", tail, 1)[0] == 20):
        raise BagError(f"{path}: truncated after {_size_text(size)} (no footer); run "
                       f"'fourws bag recover {path}'")


def read_errors() -> tuple[type[BaseException], ...]:
    """The exceptions mcap and zstandard raise for a damaged file (caught as a BagError)."""
    from mcap.exceptions import McapError

    errs: list[type[BaseException]] = [McapError, struct.error, ValueError, EOFError,
                                       UnicodeDecodeError, KeyError, IndexError]
    with contextlib.suppress(ImportError):
        import zstandard

        errs.append(zstandard.ZstdError)
    return tuple(errs)


@dataclass
class ChannelInfo:
    """A channel of an MCAP file: topic, type, schema text, offered QoS, message count."""

    topic: str
    type: str
    definition: str
    qos: dict[str, Any] | None
    message_count: int


class McapBag:
    """A finished MCAP file opened for reading (``with McapBag(path) as bag: ...``)."""

    def __init__(self, path: str | Path) -> None:
        self.path = resolve_mcap(path)
        check_mcap(self.path)
        from mcap.reader import SeekingReader

        self._fh = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        try:
            self._reader = SeekingReader(self._fh, validate_crcs=True)
            summary = self._reader.get_summary()
        except read_errors() as exc:
            self._fh.close()
            raise BagError(f"{self.path}: corrupt MCAP summary: {exc}") from exc
        if summary is None:
            self._fh.close()
            raise BagError(f"{self.path}: MCAP file without a summary section")
        self.summary = summary
        #: custom_data of the bag's rosbag2 metadata copy inside the MCAP ({} if none)
        self.custom_data: dict[str, str] = {}
        try:
            for rec in self._reader.iter_metadata():
                if rec.name == "rosbag2":
                    info = yaml.safe_load(rec.metadata.get("serialized_metadata", "")) or {}
                    self.custom_data = {str(k): str(v) for k, v in
                                        (info.get("custom_data") or {}).items()}
        except (*read_errors(), yaml.YAMLError, AttributeError):
            self.custom_data = {}
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        self.channels: dict[str, ChannelInfo] = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            self.channels[ch.topic] = ChannelInfo(
                ch.topic, schema.name if schema else "",
                schema.data.decode("utf-8", "replace") if schema else "",
                parse_offered_qos(ch.metadata.get("offered_qos_profiles", "")),
                int(counts.get(cid, 0)))

    def __enter__(self) -> McapBag:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._fh.close()

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, int, int,
                                                                              bytes]]:
        """``(topic, log_time_ns, publish_time_ns, data)`` in log-time (recorded) order."""
        topics = None if topics is None else list(topics)
        try:
            for _schema, channel, msg in self._reader.iter_messages(topics=topics,
                                                                    log_time_order=True):
                yield channel.topic, msg.log_time, msg.publish_time, msg.data
        except read_errors() as exc:
            raise BagError(f"{self.path}: corrupt data: {exc}") from exc

    def decoded(self, topics: Iterable[str] | None = None
                ) -> Iterator[tuple[str, int, int, Any]]:
        """``(topic, log_time_ns, publish_time_ns, message)`` decoded with mcap_ros2's CDR
        decoder."""
        from mcap_ros2.decoder import DecoderFactory

        factory = DecoderFactory()
        decoders: dict[int, Any] = {}
        topics = None if topics is None else list(topics)
        try:
            for schema, channel, msg in self._reader.iter_messages(topics=topics,
                                                                   log_time_order=True):
                dec = decoders.get(channel.id)
                if dec is None:
                    dec = factory.decoder_for(channel.message_encoding, schema)
                    if dec is None:
                        raise BagError(f"{self.path}: no decoder for {channel.topic} "
                                       f"({channel.message_encoding}, schema "
                                       f"{schema.encoding if schema else 'none'})")
                    decoders[channel.id] = dec
                try:
                    value = dec(msg.data)
                except read_errors() as exc:
                    raise BagError(f"{self.path}: cannot decode a message on {channel.topic} "
                                   f"at log time {msg.log_time}: {exc}") from exc
                yield channel.topic, msg.log_time, msg.publish_time, value
        except BagError:
            raise
        except read_errors() as exc:
            raise BagError(f"{self.path}: corrupt data: {exc}") from exc
