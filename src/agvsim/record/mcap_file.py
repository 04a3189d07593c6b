"""A streaming MCAP writer whose file is readable at every moment, and a repair for the rest.

MCAP (https://mcap.dev/spec) is a sequence of records ``opcode u8, length u64, content``
between two magic strings. A normal writer puts the index and the footer only at the end, so a
killed process leaves a file that most readers (``rosbags`` among them) refuse. This writer
keeps the file valid while it grows:

* messages collect in a chunk (LZ4-compressed by default) that is written when ``flush()`` is
  called (the recorder does so at least every second of simulated or wall time);
* every flush writes, in one ``write`` call, the chunk, its message indexes and a provisional
  ``DataEnd`` + ``Footer`` (no summary) + magic, over the previous provisional end. After a
  kill the file on disk is a complete MCAP file without a summary, which ``rosbags``,
  ``mcap`` and Foxglove read by scanning;
* ``close()`` replaces the provisional end with the summary (schemas, channels, statistics,
  chunk and metadata indexes, summary offsets) and the real footer.

``repair()`` fixes what even this cannot prevent (a machine that died in the middle of a
write): it cuts the file after its last complete record and appends a footer.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 1, 2, 3, 4, 5, 6
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_STATISTICS, OP_METADATA = 7, 8, 11, 12
OP_METADATA_INDEX, OP_SUMMARY_OFFSET, OP_DATA_END = 13, 14, 15


_MESSAGE_HEAD = struct.Struct("<BQHIQQ")


def _record(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


def _str(s: str) -> bytes:
    b = s.encode()
    return struct.pack("<I", len(b)) + b


def _map(d: dict[str, str]) -> bytes:
    body = b"".join(_str(k) + _str(v) for k, v in d.items())
    return struct.pack("<I", len(body)) + body


def _data_end() -> bytes:
    return _record(OP_DATA_END, struct.pack("<I", 0))


def _footer(summary_start: int = 0, summary_offset_start: int = 0, crc: int = 0) -> bytes:
    return _record(OP_FOOTER, struct.pack("<QQI", summary_start, summary_offset_start, crc))


_COMPRESSORS = {"": lambda b: b}
try:  # lz4 ships with rosbags and mcap
    import lz4.frame as _lz4

    _COMPRESSORS["lz4"] = _lz4.compress
except ImportError:  # pragma: no cover - plain chunks still work
    pass


@dataclass
class _Chunk:
    records: bytearray = field(default_factory=bytearray)
    start_ns: int = 2**64 - 1
    end_ns: int = 0
    index: dict[int, list[tuple[int, int]]] = field(default_factory=dict)

    def empty(self) -> bool:
        return not self.records


class McapStreamWriter:
    """Write an MCAP file that stays readable while it grows (see the module docstring).

    ``profile`` ``"ros2"`` with ``"ros2msg"`` schemas and ``"cdr"`` messages is what ROS 2 tools
    expect. Times are nanoseconds."""

    def __init__(
        self,
        path: str | Path,
        profile: str = "ros2",
        library: str = "agvsim",
        compression: str = "lz4",
    ):
        if compression not in _COMPRESSORS:
            raise ValueError(
                f"MCAP compression {compression!r} is not available; use one of "
                f"{sorted(_COMPRESSORS)}"
            )
        self.path = Path(path)
        self.compression = compression
        self._compress = _COMPRESSORS[compression]
        self._f = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        head = MAGIC + _record(OP_HEADER, _str(profile) + _str(library))
        self._f.write(head + _data_end() + _footer() + MAGIC)
        self._f.flush()
        self._tail = len(head)  # where the provisional end starts
        self._pending = bytearray()  # schema/channel/metadata records not yet on disk
        self._schemas: list[bytes] = []  # their records, for the summary
        self._channels: list[bytes] = []
        self._chunk_index: list[bytes] = []
        self._metadata_index: list[bytes] = []
        self._pending_meta: list[tuple[str, bytes]] = []
        self._chunk = _Chunk()
        self.channel_counts: dict[int, int] = {}
        self.message_count = 0
        self._start_ns: int | None = None
        self._end_ns = 0
        self.closed = False

    # ------------------------------------------------------------------ registration
    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        sid = len(self._schemas) + 1  # 0 means "no schema"
        rec = _record(OP_SCHEMA, struct.pack("<H", sid) + _str(name) + _str(encoding) + _lenb(data))
        self._schemas.append(rec)
        self._pending += rec
        return sid

    def add_channel(
        self,
        topic: str,
        schema_id: int,
        message_encoding: str = "cdr",
        metadata: dict[str, str] | None = None,
    ) -> int:
        cid = len(self._channels)
        rec = _record(
            OP_CHANNEL,
            struct.pack("<HH", cid, schema_id)
            + _str(topic)
            + _str(message_encoding)
            + _map(metadata or {}),
        )
        self._channels.append(rec)
        self._pending += rec
        self.channel_counts[cid] = 0
        return cid

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """A Metadata record (e.g. the scenario); written outside the chunks at the next flush."""
        rec = _record(OP_METADATA, _str(name) + _map(values))
        self._pending_meta.append((name, rec))

    # ------------------------------------------------------------------ messages
    def add_message(
        self, channel_id: int, log_time_ns: int, data: bytes, publish_time_ns: int | None = None
    ) -> None:
        ch = self._chunk
        seq = self.channel_counts[channel_id]
        self.channel_counts[channel_id] = seq + 1
        self.message_count += 1
        pub = log_time_ns if publish_time_ns is None else publish_time_ns
        records = ch.records
        idx = ch.index.get(channel_id)
        if idx is None:
            idx = ch.index[channel_id] = []
        idx.append((log_time_ns, len(records)))
        records += _MESSAGE_HEAD.pack(
            OP_MESSAGE, 22 + len(data), channel_id, seq & 0xFFFFFFFF, log_time_ns, pub
        )
        records += data
        if log_time_ns < ch.start_ns:
            ch.start_ns = log_time_ns
        if log_time_ns > ch.end_ns:
            ch.end_ns = log_time_ns

    @property
    def chunk_bytes(self) -> int:
        """Uncompressed size of the chunk being filled."""
        return len(self._chunk.records)

    # ------------------------------------------------------------------ flushing
    def flush(self) -> None:
        """Write the pending records and the current chunk; the file is valid afterwards."""
        if self.closed:
            return
        out = bytearray(self._pending)
        self._pending.clear()
        for name, rec in self._pending_meta:
            self._metadata_index.append(
                _record(
                    OP_METADATA_INDEX,
                    struct.pack("<QQ", self._tail + len(out), len(rec)) + _str(name),
                )
            )
            out += rec
        self._pending_meta.clear()
        ch = self._chunk
        if not ch.empty():
            raw = bytes(ch.records)
            packed = self._compress(raw)
            content = (
                struct.pack("<QQQI", ch.start_ns, ch.end_ns, len(raw), zlib.crc32(raw))
                + _str(self.compression)
                + struct.pack("<Q", len(packed))
                + packed
            )
            chunk_start = self._tail + len(out)
            out += _record(OP_CHUNK, content)
            chunk_len = 9 + len(content)
            offsets = {}
            idx_start = len(out)
            for cid, entries in sorted(ch.index.items()):
                offsets[cid] = self._tail + len(out)
                body = b"".join(struct.pack("<QQ", t, o) for t, o in entries)
                out += _record(OP_MESSAGE_INDEX, struct.pack("<HI", cid, len(body)) + body)
            idx_len = len(out) - idx_start
            off_map = b"".join(struct.pack("<HQ", c, o) for c, o in offsets.items())
            self._chunk_index.append(
                _record(
                    OP_CHUNK_INDEX,
                    struct.pack("<QQQQ", ch.start_ns, ch.end_ns, chunk_start, chunk_len)
                    + struct.pack("<I", len(off_map))
                    + off_map
                    + struct.pack("<Q", idx_len)
                    + _str(self.compression)
                    + struct.pack("<QQ", len(packed), len(raw)),
                )
            )
            if self._start_ns is None or ch.start_ns < self._start_ns:
                self._start_ns = ch.start_ns
            self._end_ns = max(self._end_ns, ch.end_ns)
            self._chunk = _Chunk()
        if not out:
            return
        self._f.seek(self._tail)
        self._f.write(bytes(out) + _data_end() + _footer() + MAGIC)
        self._f.flush()
        self._tail += len(out)

    def close(self) -> None:
        """Flush, then write the summary and the real footer."""
        if self.closed:
            return
        self.flush()
        f = self._f
        f.seek(self._tail)
        end = _data_end()
        summary_start = self._tail + len(end)
        summary = bytearray()
        groups: list[tuple[int, int, int]] = []

        def group(op: int, records: list[bytes]) -> None:
            if records:
                groups.append((op, summary_start + len(summary), sum(len(r) for r in records)))
                for r in records:
                    summary.extend(r)

        group(OP_SCHEMA, self._schemas)
        group(OP_CHANNEL, self._channels)
        counts = b"".join(struct.pack("<HQ", c, n) for c, n in self.channel_counts.items())
        stats = _record(
            OP_STATISTICS,
            struct.pack(
                "<QHIIIIQQ",
                self.message_count,
                len(self._schemas),
                len(self._channels),
                0,
                len(self._metadata_index),
                len(self._chunk_index),
                self._start_ns or 0,
                self._end_ns,
            )
            + struct.pack("<I", len(counts))
            + counts,
        )
        group(OP_STATISTICS, [stats])
        group(OP_CHUNK_INDEX, self._chunk_index)
        group(OP_METADATA_INDEX, self._metadata_index)
        offset_start = summary_start + len(summary)
        for op, start, length in groups:
            summary += _record(OP_SUMMARY_OFFSET, struct.pack("<BQQ", op, start, length))
        foot_fields = struct.pack("<BQQQ", OP_FOOTER, 20, summary_start, offset_start)
        crc = zlib.crc32(bytes(summary) + foot_fields)
        f.write(end + bytes(summary) + foot_fields + struct.pack("<I", crc) + MAGIC)
        f.truncate()
        f.close()
        self.closed = True

    def __enter__(self) -> McapStreamWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _lenb(data: bytes) -> bytes:
    return struct.pack("<I", len(data)) + data


# ---------------------------------------------------------------------- inspection and repair
def scan_records(path: str | Path) -> tuple[list[tuple[int, int, int]], int, bool]:
    """Walk the records of an MCAP file: ``([(opcode, offset, total_length)], end_of_last_
    complete_record, has_footer)``. Stops at the footer or at the first truncated record.
    Reads only the record headers."""
    with open(path, "rb") as f:
        size = f.seek(0, 2)
        f.seek(0)
        if f.read(len(MAGIC)) != MAGIC:
            raise ValueError(f"{path}: not an MCAP file (no magic at the start)")
        pos, out = len(MAGIC), []
        while pos + 9 <= size:
            f.seek(pos)
            op, length = struct.unpack("<BQ", f.read(9))
            if op == 0 or pos + 9 + length > size:
                break
            out.append((op, pos, 9 + length))
            pos += 9 + length
            if op == OP_FOOTER:
                f.seek(pos)
                return out, pos, f.read(8) == MAGIC
    return out, pos, False


def repair(path: str | Path, out_path: str | Path | None = None) -> int:
    """Make a cut-off MCAP file readable: keep every complete record before the cut (a chunk
    that was half written is dropped), drop an old data end, append ``DataEnd``, a footer
    without summary and the magic. Writes ``out_path`` (default: in place). Returns the number
    of bytes kept. A file that already ends in a footer is copied unchanged."""
    src = Path(path)
    records, end, complete = scan_records(src)
    data = src.read_bytes()
    dst = Path(out_path) if out_path is not None else src
    if complete:
        if dst != src:
            dst.write_bytes(data)
        return len(data)
    keep = end
    # drop a trailing DataEnd / summary part so the data end is written once
    for op, off, _length in reversed(records):
        if op in (OP_DATA_END, OP_SUMMARY_OFFSET, OP_STATISTICS, OP_CHUNK_INDEX):
            keep = off
        else:
            break
    fixed = data[:keep] + _data_end() + _footer() + MAGIC
    dst.write_bytes(fixed)
    return keep
