"""Recovery of a truncated bag: :func:`recover` a file, :func:`recover_folder` in place.

:func:`recover` rewrites every complete record of a (truncated) MCAP file as a whole, valid
file; :func:`recover_folder` does that in place in a bag folder (the cut original kept
aside) and rewrites its metadata.yaml from the file; :func:`in_bag_folder` tells which
paths it repairs in place (docs/bags.md, "Recovery").
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from fourws_common.topics import TopicInfo, offered_qos

from .errors import BagError
from .metadata import TopicRecord, parse_offered_qos, write_metadata
from .reader import MCAP_MAGIC, McapBag, check_mcap, read_errors, resolve_mcap
from .writer import compression_type


def recover(src: str | Path, dst: str | Path, *, compression: str = "zstd",
            chunk_size_bytes: int = 1024 * 1024) -> int:
    """Rewrite every complete record of a (truncated) MCAP file as a whole, valid file.

    Reads ``src`` front to back (non-seeking), keeps schemas, channels, metadata and the
    messages of every chunk that is complete and whose CRC checks, and stops cleanly at the
    first incomplete or damaged record. Returns the number of messages written to ``dst``.
    """
    from mcap.records import (
        Attachment,
        Channel,
        DataEnd,
        Footer,
        Header,
        Message,
        Metadata,
        Schema,
    )
    from mcap.stream_reader import StreamReader

    src_path = resolve_mcap(src)
    dst_path = Path(dst)
    if dst_path.resolve() == src_path.resolve():
        raise BagError(f"{src_path}: recover needs another output file")
    with open(src_path, "rb") as fh:
        if fh.read(8) != MCAP_MAGIC:
            raise BagError(f"{src_path}: not an MCAP file (bad magic); nothing to recover")
        fh.seek(0)
        size = os.fstat(fh.fileno()).st_size
        records = StreamReader(fh, validate_crcs=True, record_size_limit=size).records
        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        kept: list[Any] = []
        header = None
        errors = read_errors()
        while True:
            try:
                rec = next(records)
            except StopIteration:
                break
            except errors:
                break  # the first incomplete or damaged record: keep what came before
            if isinstance(rec, Header):
                header = rec
            elif isinstance(rec, Schema):
                schemas.setdefault(rec.id, rec)
            elif isinstance(rec, Channel):
                channels.setdefault(rec.id, rec)
            elif isinstance(rec, Message | Attachment) or (
                    isinstance(rec, Metadata) and rec.name != "rosbag2"):
                kept.append(rec)
            elif isinstance(rec, DataEnd | Footer):
                break
    tmp = dst_path.with_name(dst_path.name + ".tmp")
    try:
        count = _write(tmp, header, schemas, channels, kept, chunk_size_bytes, compression)
        os.replace(tmp, dst_path)
    finally:
        tmp.unlink(missing_ok=True)      # a full disk leaves no half file behind
    return count


def _write(tmp: Path, header, schemas: dict, channels: dict, kept: list,
           chunk_size_bytes: int, compression: str) -> int:
    """The kept records into a new MCAP file ``tmp``; the messages written."""
    from mcap.records import Attachment, Message, Metadata
    from mcap.writer import Writer

    count = 0
    with open(tmp, "wb") as out:
        w = Writer(out, chunk_size=chunk_size_bytes, compression=compression_type(compression))
        w.start(profile=header.profile if header else "ros2",
                library=(header.library if header else "unknown") + "; fourws recover")
        schema_ids = {sid: w.register_schema(s.name, s.encoding, s.data)
                      for sid, s in sorted(schemas.items())}
        channel_ids = {cid: w.register_channel(c.topic, c.message_encoding,
                                               schema_ids.get(c.schema_id, 0), c.metadata)
                       for cid, c in sorted(channels.items())}
        for rec in kept:
            if isinstance(rec, Message):
                if rec.channel_id not in channel_ids:
                    continue
                w.add_message(channel_ids[rec.channel_id], rec.log_time, rec.data,
                              rec.publish_time, rec.sequence)
                count += 1
            elif isinstance(rec, Metadata):
                w.add_metadata(rec.name, rec.metadata)
            elif isinstance(rec, Attachment):
                w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type,
                                 rec.data)
        w.finish()
    return count


@dataclass(frozen=True)
class FolderRecovery:
    """What :func:`recover_folder` did: the bag's MCAP file (whole now), its rewritten
    metadata.yaml, the messages in the file, and where the cut file went (None: it was
    whole already and is untouched)."""

    mcap: Path
    metadata: Path
    messages: int
    kept_aside: Path | None


def in_bag_folder(path: str | Path) -> bool:
    """Whether ``path`` is a folder (a run or bag folder) or the ``.mcap`` of a bag folder
    (a metadata.yaml beside it): :func:`recover_folder` repairs those in place."""
    p = Path(path)
    return p.is_dir() or (p.suffix == ".mcap" and (p.parent / "metadata.yaml").is_file())


def _unused(path: Path) -> Path:
    """``path``, or ``path.1``, ``path.2``... whichever does not exist yet."""
    candidate, i = path, 0
    while candidate.exists():
        i += 1
        candidate = path.with_name(f"{path.name}.{i}")
    return candidate


def recover_folder(path: str | Path, *, compression: str = "zstd") -> FolderRecovery:
    """Repair a bag folder in place so every rosbag2 reader takes it whole.

    ``path`` is a run folder, a bag folder or the ``.mcap`` inside one. A truncated file is
    rewritten by :func:`recover` under its own name (so ``relative_file_paths`` stays
    right) and the cut original is moved aside to ``NAME.mcap.truncated`` (not listed in
    metadata.yaml, nothing lost). Then ``metadata.yaml`` is written from the file itself:
    per-topic message counts, types, offered QoS and type hashes from its channels,
    starting time and duration from its statistics; ``custom_data`` keeps what it held,
    with ``fourws_state: recovered`` (``complete`` for a file that was whole already) and
    ``fourws_recovered_from`` naming the cut file.
    """
    p = Path(path)
    mcap = p if p.is_file() else resolve_mcap(p)
    folder = mcap.parent
    try:
        check_mcap(mcap)
        kept = None
    except BagError:
        kept = _unused(mcap.with_name(mcap.name + ".truncated"))
        fixed = _unused(mcap.with_name(mcap.name + ".recovered"))
        recover(mcap, fixed, compression=compression)
        os.replace(mcap, kept)
        os.replace(fixed, mcap)
    meta_path = folder / "metadata.yaml"
    custom: dict[str, str] = {}
    with contextlib.suppress(OSError, yaml.YAMLError, AttributeError, TypeError):
        old = yaml.safe_load(meta_path.read_text(encoding="utf-8"))
        custom = {str(k): str(v) for k, v in
                  (old["rosbag2_bagfile_information"].get("custom_data") or {}).items()}
    custom["fourws_state"] = "complete" if kept is None else "recovered"
    if kept is not None:
        custom["fourws_recovered_from"] = kept.name
    with McapBag(mcap) as bag:
        summary = bag.summary
        stats = summary.statistics
        counts = stats.channel_message_counts if stats else {}
        topics = []
        for cid, ch in sorted(summary.channels.items()):
            schema = summary.schemas.get(ch.schema_id)
            typ = schema.name if schema else ""
            qos = parse_offered_qos(ch.metadata.get("offered_qos_profiles", "")) \
                or offered_qos(ch.topic)
            topics.append(TopicRecord(TopicInfo(ch.topic, typ, qos), int(counts.get(cid, 0)),
                                      ch.metadata.get("topic_type_hash", "")))
        start = int(stats.message_start_time) if stats else 0
        end = int(stats.message_end_time) if stats else 0
    total = sum(t.message_count for t in topics)
    write_metadata(folder, relative_file_paths=[mcap.name], topics=topics,
                   starting_time_ns=start, duration_ns=end - start, custom_data=custom)
    return FolderRecovery(mcap, meta_path, total, kept)
