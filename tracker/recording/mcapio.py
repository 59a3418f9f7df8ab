"""MCAP on disk: a chunked writer that survives being killed, and a reader that survives truncation.

The writer is built from the ``mcap`` package's record classes rather than its ``Writer``
because a recording needs three things that class does not offer: chunks closed by
time (about one second each) and written to the OS as soon as they are closed, so a
SIGKILL loses at most the chunk in progress; compression of a chunk in another thread
than the one that builds the next (the ``ChunkBuilder``/``write_chunk`` split); and the
choice of compression level and threads. Schemas, channels, metadata and attachments
go in the data section before the first chunk, so a file cut anywhere after them still
says how to decode and replay everything before the cut. The summary and footer
written by ``finish`` make the file seekable (Foxglove, ``mcap`` readers).
"""

from __future__ import annotations

import errno
import io
import mmap
import os
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, BinaryIO, Protocol

import lz4.frame
import zstandard
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.exceptions import EndOfFile, McapError
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import StreamReader, breakup_chunk

from tracker import __version__

MAGIC = bytes((0x89, ord("M"), ord("C"), ord("A"), ord("P"), ord("0"), 0x0D, 0x0A))
LIBRARY = f"belt-tracker/{__version__}"
COMPRESSIONS = ("zstd", "lz4", "none")
# MCAP opcodes of the summary groups (spec), for the summary offsets.
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK, _OP_CHUNK_INDEX = 0x03, 0x04, 0x05, 0x06, 0x08
_OP_ATTACHMENT_INDEX, _OP_STATISTICS, _OP_METADATA_INDEX = 0x0A, 0x0B, 0x0D


class Output(Protocol):
    def write(self, data: bytes | memoryview) -> Any: ...


class RawFile:
    """An unbuffered file: every ``write`` reaches the OS before it returns (no Python buffer
    to lose on SIGKILL), and a failed write can be undone with ``truncate``."""

    def __init__(self, path: str | os.PathLike) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)

    def write(self, data: bytes | memoryview) -> int:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            if n == 0:  # a regular file only writes short when it is out of space
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            view = view[n:]
        return len(data)

    def truncate(self, size: int) -> None:
        os.ftruncate(self._fd, size)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


@dataclass(frozen=True)
class Compression:
    kind: str = "zstd"
    level: int = 1
    # zstd worker threads (0: compress in the calling thread).
    threads: int = 0

    def __post_init__(self) -> None:
        if self.kind not in COMPRESSIONS:
            raise ValueError(f"compression: expected one of {COMPRESSIONS}, got {self.kind!r}")

    @property
    def name(self) -> str:
        return "" if self.kind == "none" else self.kind

    def compress(self, data: memoryview) -> bytes:
        """One call for the whole chunk: each call into C releases Python's lock and must win
        it back from a busy loop thread (up to the 5 ms switch interval), so calls per chunk,
        not bytes, decide how long the recorder's threads wait."""
        if self.kind == "zstd":
            # zstd's own content checksum (xxHash, computed as it compresses) detects damage at
            # decompression; it stands in for the chunk's CRC-32, which costs 0.4 ms per 720p frame.
            return zstandard.ZstdCompressor(level=self.level, threads=self.threads, write_checksum=True).compress(data)
        return lz4.frame.compress(data) if self.kind == "lz4" else bytes(data)


# Fixed parts of a Message record (opcode, length, channel, sequence, log and publish time)
# and of a Chunk record up to its records (MCAP spec).
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")
_CHUNK_FIXED = struct.Struct("<BQQQQI")


class OpenChunk:
    """Messages of one chunk, serialised into one buffer, not yet compressed. The buffer is
    allocated once at its expected size: growing a bytearray frame by frame copies it over and
    over (2 ms per 720p frame measured)."""

    def __init__(self, capacity: int = 1 << 20, buffer: bytearray | None = None) -> None:
        # A buffer handed back by an earlier chunk is reused: a new one is zeroed page by page
        # (36 ms for a 720p chunk, 0.6 ms a frame, with Python's lock held).
        self.buffer = buffer if buffer is not None and len(buffer) >= capacity else bytearray(capacity)
        self.size = 0
        self.start_ns = self.end_ns = 0
        self.messages = 0
        self.index: dict[int, list[tuple[int, int]]] = {}
        self.per_channel: dict[int, int] = {}

    @property
    def data(self) -> memoryview:
        return memoryview(self.buffer)[:self.size]

    def _put(self, data: bytes | memoryview) -> None:
        end = self.size + len(data)
        if end > len(self.buffer):
            self.buffer.extend(bytes(max(end - len(self.buffer), len(self.buffer) // 2)))
        self.buffer[self.size:end] = data
        self.size = end

    def add(self, channel_id: int, log_time_ns: int, data: bytes | tuple, sequence: int = 0) -> None:
        """One message; ``data`` is its bytes, or a tuple of pieces to concatenate."""
        pieces = data if isinstance(data, tuple) else (data,)
        length = sum(len(p) for p in pieces)
        if self.messages == 0:
            self.start_ns = self.end_ns = log_time_ns
        self.start_ns = min(self.start_ns, log_time_ns)
        self.end_ns = max(self.end_ns, log_time_ns)
        self.index.setdefault(channel_id, []).append((log_time_ns, self.size))
        self.per_channel[channel_id] = self.per_channel.get(channel_id, 0) + 1
        self.messages += 1
        self._put(_MESSAGE_HEAD.pack(_OP_MESSAGE, 2 + 4 + 8 + 8 + length, channel_id, sequence & 0xFFFFFFFF,
                                     log_time_ns, log_time_ns))
        for piece in pieces:
            self._put(piece)


class McapWriter:
    """Writes records to ``out`` (anything with ``write(bytes)``); keeps the offsets itself."""

    def __init__(self, out: Output, compression: Compression | None = None) -> None:
        self._out = out
        self._compression = compression or Compression()
        self._compression_name = self._compression.name
        self.bytes_written = 0
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._stats = Statistics(message_count=0, schema_count=0, channel_count=0, attachment_count=0,
                                 metadata_count=0, chunk_count=0, message_start_time=0, message_end_time=0,
                                 channel_message_counts={})
        self._builder = RecordBuilder()

    def _emit(self) -> int:
        """Write what the record builder holds; returns the offset it was written at."""
        data = self._builder.end()
        offset = self.bytes_written
        self._out.write(data)
        self.bytes_written += len(data)
        return offset

    def start(self) -> None:
        self._out.write(MAGIC)
        self.bytes_written += len(MAGIC)
        Header(profile="", library=LIBRARY).write(self._builder)
        self._emit()

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._stats.schema_count += 1
        schema.write(self._builder)
        self._emit()
        return schema.id

    def add_channel(self, topic: str, message_encoding: str, schema_id: int) -> int:
        channel = Channel(id=len(self._channels) + 1, topic=topic, message_encoding=message_encoding,
                          schema_id=schema_id, metadata={})
        self._channels.append(channel)
        self._stats.channel_count += 1
        channel.write(self._builder)
        self._emit()
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        Metadata(name=name, metadata=data).write(self._builder)
        length = self._builder.count
        offset = self._emit()
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=length, name=name))
        self._stats.metadata_count += 1

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time_ns: int = 0) -> None:
        Attachment(create_time=log_time_ns, log_time=log_time_ns, name=name, media_type=media_type,
                   data=data).write(self._builder)
        length = self._builder.count
        offset = self._emit()
        self._attachment_indexes.append(AttachmentIndex(
            offset=offset, length=length, create_time=log_time_ns, log_time=log_time_ns,
            data_size=len(data), name=name, media_type=media_type))
        self._stats.attachment_count += 1

    def write_chunk(self, chunk: OpenChunk) -> None:
        """Compress and write one chunk, then its message indexes."""
        if chunk.messages == 0:
            return
        # 0: "not computed" (MCAP spec) where the compression checks the data itself.
        crc = 0 if self._compression.kind == "zstd" else zlib.crc32(chunk.data)
        packed = self._compression.compress(chunk.data)
        name = self._compression_name.encode()
        body = 8 + 8 + 8 + 4 + 4 + len(name) + 8 + len(packed)
        head = _CHUNK_FIXED.pack(_OP_CHUNK, body, chunk.start_ns, chunk.end_ns, chunk.size, crc) \
            + len(name).to_bytes(4, "little") + name + len(packed).to_bytes(8, "little")
        chunk_offset = self.bytes_written
        chunk_length = len(head) + len(packed)
        self._out.write(head)
        self._out.write(packed)
        self.bytes_written += chunk_length
        offsets = {}
        index_start = self.bytes_written
        for channel_id, records in sorted(chunk.index.items()):
            offsets[channel_id] = index_start + self._builder.count
            MessageIndex(channel_id=channel_id, records=records).write(self._builder)
        index_length = self._builder.count
        self._emit()
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=chunk.start_ns, message_end_time=chunk.end_ns, chunk_start_offset=chunk_offset,
            chunk_length=chunk_length, message_index_offsets=offsets, message_index_length=index_length,
            compression=self._compression_name, compressed_size=len(packed), uncompressed_size=chunk.size))
        s = self._stats
        if s.message_count == 0:
            s.message_start_time = chunk.start_ns
        s.message_start_time = min(s.message_start_time, chunk.start_ns)
        s.message_end_time = max(s.message_end_time, chunk.end_ns)
        s.message_count += chunk.messages
        s.chunk_count += 1
        for channel_id, n in chunk.per_channel.items():
            s.channel_message_counts[channel_id] = s.channel_message_counts.get(channel_id, 0) + n

    def finish(self) -> None:
        """Data end, summary (schemas, channels, statistics, indexes, offsets), footer, magic."""
        DataEnd(data_section_crc=0).write(self._builder)
        self._emit()
        summary_start = self.bytes_written
        b = self._builder
        groups = []
        for opcode, records in ((_OP_SCHEMA, self._schemas), (_OP_CHANNEL, self._channels),
                                (_OP_STATISTICS, [self._stats]), (_OP_CHUNK_INDEX, self._chunk_indexes),
                                (_OP_ATTACHMENT_INDEX, self._attachment_indexes),
                                (_OP_METADATA_INDEX, self._metadata_indexes)):
            if not records:
                continue
            start = b.count
            for record in records:
                record.write(b)
            groups.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                        group_length=b.count - start))
        offsets_start = summary_start + b.count
        for group in groups:
            group.write(b)
        summary = b.end()
        # The footer's CRC covers the summary and the footer's own fields up to the CRC.
        footer_head = bytes([0x02]) + (20).to_bytes(8, "little") + summary_start.to_bytes(8, "little") \
            + offsets_start.to_bytes(8, "little")
        crc = zlib.crc32(footer_head, zlib.crc32(summary))
        self._out.write(summary)
        self.bytes_written += len(summary)
        Footer(summary_start=summary_start, summary_offset_start=offsets_start, summary_crc=crc).write(b)
        self._emit()
        self._out.write(MAGIC)
        self.bytes_written += len(MAGIC)


# --- reading ------------------------------------------------------------------------------------

class _Exact:
    """A file whose ``read(n)`` returns n bytes or raises EndOfFile: the ``mcap`` stream reader
    only notices an empty read, and would otherwise parse a record cut short as if whole."""

    def __init__(self, f: BinaryIO) -> None:
        self._f = f
        self.position = 0

    def read(self, n: int) -> bytes:
        data = self._f.read(n)
        self.position += len(data)
        if len(data) < n:
            raise EndOfFile()
        return data


@dataclass
class ReadEnd:
    """How a sequential read ended."""

    complete: bool = False  # the footer and the whole closing magic were read
    truncated: bool = False  # the file ends inside (or instead of) a record
    damaged: str = ""  # a record could not be decoded (CRC, compression, format, a length past the end)
    position: int = 0  # bytes read; where the damage is, when damaged

    def describe(self, path: str) -> str:
        if self.complete:
            return f"{path}: complete"
        if self.damaged:
            return f"{path}: damaged at byte {self.position}: {self.damaged}"
        return f"{path}: ends at byte {self.position} without its summary (cut short: the last chunk is incomplete)"


def iter_records(f: BinaryIO, end: ReadEnd, emit_chunks: bool = False) -> Iterator[Any]:
    """Every record of an MCAP stream in file order (messages taken out of their chunks,
    CRC-checked); stops quietly at a truncation or damage and says which in ``end``.

    A record whose length points past the end of the file looks like a file cut short. It is
    damage when valid data follows (a chunk whose CRC checks, or the closing footer): a cut
    file has nothing after its last record."""
    exact = _Exact(f)
    reader = StreamReader(exact, emit_chunks=emit_chunks, validate_crcs=True)
    good = 0  # where the record being read begins: the end of the last one read whole
    footer = False
    try:
        for record in reader.records:
            good = exact.position
            end.position = good
            yield record
            if isinstance(record, Footer):
                footer = True
        # The stream reader returns only after the closing magic: a file cut inside it is not complete.
        end.complete = footer
        end.truncated = not footer
        end.position = exact.position
    except EndOfFile:
        following = valid_data_after(f, good) if good else None
        if following is None:
            end.truncated = True
            end.position = exact.position
        else:
            end.damaged = (f"the record there cannot be read (its length or type is wrong), yet valid data "
                           f"follows at byte {following}")
            end.position = good
    except (McapError, ValueError, zstandard.ZstdError, RuntimeError, UnicodeDecodeError, KeyError,
            struct.error) as exc:
        end.damaged = str(exc) or type(exc).__name__
        end.position = good


# A chunk record up to its compression name: opcode, length, start and end time,
# uncompressed size and CRC, then the name's length (MCAP spec).
_CHUNK_HEAD = 1 + 8 + 8 + 8 + 8 + 4
_FOOTER_RECORD = 1 + 8 + 20
# Candidate chunks checked when looking for valid data behind damage (each is decompressed).
_MAX_CANDIDATES = 64


def valid_data_after(f: BinaryIO, start: int) -> int | None:
    """The offset of the closing footer or of a valid chunk after ``start``, else None."""
    try:
        size = os.fstat(f.fileno()).st_size
    except (OSError, AttributeError, ValueError):
        return None
    if size <= start + 1:
        return None
    with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as m:
        footer = size - len(MAGIC) - _FOOTER_RECORD
        if footer > start and m[size - len(MAGIC):] == MAGIC and m[footer] == 0x02 \
                and int.from_bytes(m[footer + 1:footer + 9], "little") == 20:
            return footer
        for name in ("zstd", "lz4"):
            pattern = len(name).to_bytes(4, "little") + name.encode()
            found, tries = m.find(pattern, start + 1), 0
            while found >= 0 and tries < _MAX_CANDIDATES:
                tries += 1
                head = found + 4 - _CHUNK_HEAD
                if head > start and m[head] == _OP_CHUNK and _chunk_ok(m, head, size):
                    return head
                found = m.find(pattern, found + 1)
    return None


def _chunk_ok(m: mmap.mmap, head: int, size: int) -> bool:
    length = int.from_bytes(m[head + 1:head + 9], "little")
    if head + 9 + length > size:
        return False
    try:
        chunk = Chunk.read(ReadDataStream(io.BytesIO(m[head + 9:head + 9 + length])))
        breakup_chunk(chunk, validate_crc=True)
    except Exception:  # noqa: BLE001 - any failure means: not a valid chunk
        return False
    return True
