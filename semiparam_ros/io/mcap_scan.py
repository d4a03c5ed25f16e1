"""Sequential MCAP scan that recovers the messages of a truncated or partly corrupt file.

A recording cut short (robot powered off, recorder killed) has no MCAP footer and no summary, and readers
that start from the summary refuse it. This module walks the records from the start of the file instead
(MCAP spec: ``<magic> [<opcode u8> <length u64> <content>]* <footer> <magic>``), so every message whose
bytes are complete before the cut is recovered:

* a record cut short ends the scan (the last chunk, if cut, yields the messages decoded before the cut:
  uncompressed, zstd and lz4 chunks are decoded as a stream);
* a chunk whose data do not decompress, fail their CRC, or hold damaged records is skipped whole, and the
  scan goes on with the next record (its length field is intact). Chunks written without a CRC (rosbags
  writes none) are checked by their framing only: damage that keeps the framing intact goes unnoticed;
* a record length that runs past the end of the file ends the scan (nothing after it can be located).

Messages come out in file order, each chunk's messages sorted by log time: for a recorder that writes in
arrival order (``ros2 bag record``, :class:`~semiparam_ros.io.bags.BagWriter`) that is log-time order.
Memory is one chunk (≈1 MB) at a time. What was recovered and what was lost is in :attr:`McapScan.report`.
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

__all__ = ["MCAP_MAGIC", "McapScan", "ScanReport", "ScannedChannel"]

MCAP_MAGIC = b"\x89MCAP0\r\n"

_OP_FOOTER = 0x02
_OP_SCHEMA = 0x03
_OP_CHANNEL = 0x04
_OP_MESSAGE = 0x05
_OP_CHUNK = 0x06
_OP_DATA_END = 0x0F
_RECORD_HEADER = struct.Struct("<BQ")
_MESSAGE_HEADER = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time
_CHUNK_HEADER = struct.Struct("<QQQI")  # message start/end time, uncompressed size, uncompressed crc


@dataclass(frozen=True)
class ScannedChannel:
    """A channel of the file with its schema (only the fields a ROS 2 reader needs).

    Attributes:
        id: Channel id.
        topic: Topic name.
        msgtype: Schema name, e.g. ``"sensor_msgs/msg/JointState"``.
        schema_encoding: E.g. ``"ros2msg"``.
        schema_data: The message definition text.
    """

    id: int
    topic: str
    msgtype: str
    schema_encoding: str
    schema_data: str


@dataclass
class ScanReport:
    """What a scan recovered and what it could not.

    Attributes:
        file_size: Bytes in the file.
        complete: True if the scan reached the footer (the file is whole).
        stop_reason: Why the scan ended before the footer ("" if complete).
        stop_offset: File offset where it ended.
        n_messages: Messages yielded (on the requested channels).
        first_log_time_ns: Log time of the earliest yielded message (None if none).
        last_log_time_ns: Log time of the latest yielded message (None if none).
        skipped: ``(file offset, reason)`` of every chunk skipped or cut short.
    """

    file_size: int = 0
    complete: bool = False
    stop_reason: str = ""
    stop_offset: int = 0
    n_messages: int = 0
    first_log_time_ns: int | None = None
    last_log_time_ns: int | None = None
    skipped: list[tuple[int, str]] = field(default_factory=list)

    @property
    def span_s(self) -> float:
        """Log-time span of the yielded messages, s (0 for fewer than two)."""
        if self.first_log_time_ns is None or self.last_log_time_ns is None:
            return 0.0
        return (self.last_log_time_ns - self.first_log_time_ns) * 1e-9


class _DamagedRecordError(Exception):
    """Internal: a record's content does not parse."""


class McapScan:
    """One sequential pass over an MCAP file (see the module docstring).

    Args:
        path: The ``.mcap`` file.

    Raises:
        OSError: If the file cannot be opened.
        ValueError: If the file does not start with the MCAP magic (then nothing can be recovered).
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.channels: dict[int, ScannedChannel] = {}
        self.report = ScanReport(file_size=self.path.stat().st_size)
        with self.path.open("rb") as fh:
            if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                raise ValueError(f"{str(self.path)!r} does not start with the MCAP magic")
        self._schemas: dict[int, tuple[str, str, str]] = {}

    def messages(self, topics: set[str] | None = None) -> Iterator[tuple[ScannedChannel, int, bytes]]:
        """Yield ``(channel, log_time_ns, data)`` of every recoverable message, in file order.

        Args:
            topics: Only these topics (default all).

        Returns:
            An iterator; :attr:`report` is final once it is exhausted.
        """
        with self.path.open("rb") as fh:
            fh.seek(len(MCAP_MAGIC))
            for channel, log_time, data in self._records(fh):
                if topics is not None and channel.topic not in topics:
                    continue
                rep = self.report
                rep.n_messages += 1
                if rep.first_log_time_ns is None or log_time < rep.first_log_time_ns:
                    rep.first_log_time_ns = log_time
                if rep.last_log_time_ns is None or log_time > rep.last_log_time_ns:
                    rep.last_log_time_ns = log_time
                yield channel, log_time, data

    # ------------------------------------------------------------------ outer records
    def _stop(self, offset: int, reason: str) -> None:
        self.report.stop_offset, self.report.stop_reason = offset, reason

    def _records(self, fh: BinaryIO) -> Iterator[tuple[ScannedChannel, int, bytes]]:
        size = self.report.file_size
        while True:
            offset = fh.tell()
            head = fh.read(_RECORD_HEADER.size)
            if len(head) < _RECORD_HEADER.size:
                self._stop(offset, "file ends without an MCAP footer" if not head
                           else "file ends inside a record header")
                return
            op, length = _RECORD_HEADER.unpack(head)
            if op in (_OP_FOOTER, _OP_DATA_END):
                self.report.complete = True
                self.report.stop_offset = offset
                return
            available = size - offset - _RECORD_HEADER.size
            if length > available and op != _OP_CHUNK:
                self._stop(offset, f"record (opcode 0x{op:02x}) of {length} bytes runs past the end of "
                                   "the file")
                return
            if op == _OP_CHUNK:
                cut = length > available
                body = fh.read(min(length, available))
                msgs = self._chunk(body, offset, cut)
                msgs.sort(key=lambda m: m[1])
                yield from msgs
                if cut:
                    self._stop(offset, "file ends inside a chunk")
                    return
                continue
            body = fh.read(length)
            try:
                if op == _OP_MESSAGE:
                    msg = self._message(body)
                    if msg is not None:
                        yield msg
                else:
                    self._definition(op, body)
            except _DamagedRecordError as err:
                self.report.skipped.append((offset, f"damaged record (opcode 0x{op:02x}): {err}"))

    # ------------------------------------------------------------------ record contents
    def _definition(self, op: int, body: bytes) -> None:
        """Register a schema or channel record (other opcodes are ignored)."""
        try:
            if op == _OP_SCHEMA:
                (sid,) = struct.unpack_from("<H", body, 0)
                name, pos = _string(body, 2)
                encoding, pos = _string(body, pos)
                (n,) = struct.unpack_from("<I", body, pos)
                data = body[pos + 4 : pos + 4 + n].decode("utf-8", errors="replace")
                self._schemas[sid] = (name, encoding, data)
            elif op == _OP_CHANNEL:
                cid, sid = struct.unpack_from("<HH", body, 0)
                topic, _ = _string(body, 4)
                name, encoding, data = self._schemas.get(sid, ("", "", ""))
                self.channels[cid] = ScannedChannel(cid, topic, name, encoding, data)
        except (struct.error, UnicodeDecodeError) as err:
            raise _DamagedRecordError(str(err)) from err

    def _message(self, body: bytes) -> tuple[ScannedChannel, int, bytes] | None:
        if len(body) < _MESSAGE_HEADER.size:
            raise _DamagedRecordError(f"message record of {len(body)} bytes")
        cid, _seq, log_time, _pub = _MESSAGE_HEADER.unpack_from(body, 0)
        channel = self.channels.get(cid)
        if channel is None:
            return None  # its channel record was lost with a skipped chunk
        return channel, int(log_time), bytes(body[_MESSAGE_HEADER.size :])

    def _chunk(self, body: bytes, offset: int, cut: bool) -> list[tuple[ScannedChannel, int, bytes]]:
        """Decode one chunk (``cut``: the file ends inside it) into its messages."""
        skipped = self.report.skipped
        try:
            _start, _end, usize, crc = _CHUNK_HEADER.unpack_from(body, 0)
            compression, pos = _string(body, _CHUNK_HEADER.size)
            (n,) = struct.unpack_from("<Q", body, pos)
        except (struct.error, UnicodeDecodeError):
            skipped.append((offset, "chunk header cut short" if cut else "damaged chunk header"))
            return []
        data = body[pos + 8 : pos + 8 + n]
        partial = cut or len(data) < n
        try:
            records = _decompress(data, compression, usize, crc, partial)
        except Exception as err:  # zstd/lz4 raise their own error types
            skipped.append((offset, f"chunk not decodable ({compression or 'uncompressed'}): {err}"))
            return []
        out: list[tuple[ScannedChannel, int, bytes]] = []
        pos, end = 0, len(records)
        while pos + _RECORD_HEADER.size <= end:
            op, length = _RECORD_HEADER.unpack_from(records, pos)
            start = pos + _RECORD_HEADER.size
            if length > end - start:
                if partial:
                    break  # the cut: what precedes it is genuine
                # Damaged framing in a whole chunk: without a CRC nothing in it can be trusted.
                skipped.append((offset, f"damaged chunk skipped: inner record of {length} bytes at {pos}"))
                return []
            content = records[start : start + length]
            pos = start + length
            try:
                if op == _OP_MESSAGE:
                    msg = self._message(content)
                    if msg is not None:
                        out.append(msg)
                else:
                    self._definition(op, content)
            except _DamagedRecordError as err:
                if partial:
                    break
                skipped.append((offset, f"damaged chunk skipped: {err}"))
                return []
        if partial:
            skipped.append((offset, f"chunk cut short: {len(out)} messages decoded before the cut"))
        return out


def _string(buf: bytes, pos: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", buf, pos)
    if pos + 4 + n > len(buf):
        raise struct.error("string runs past its record")
    return bytes(buf[pos + 4 : pos + 4 + n]).decode("utf-8"), pos + 4 + n


def _decompress(data: bytes, compression: str, usize: int, crc: int, partial: bool) -> bytes:
    """Decompress a chunk's records; a ``partial`` one as far as its data go (no CRC check then)."""
    if compression == "":
        out = bytes(data)
    elif compression == "zstd":
        import zstandard

        if partial:
            out = zstandard.ZstdDecompressor().decompressobj().decompress(data)
        else:
            out = zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
    elif compression == "lz4":
        import lz4.frame

        if partial:
            out = lz4.frame.LZ4FrameDecompressor().decompress(data)
        else:
            out = lz4.frame.decompress(data)
    else:
        raise ValueError(f"unsupported chunk compression {compression!r}")
    if not partial:
        if len(out) != usize:
            raise ValueError(f"decompressed to {len(out)} bytes, expected {usize}")
        if crc and zlib.crc32(out) != crc:
            raise ValueError("CRC mismatch")
    return out
