"""MCAP drive logs read record by record, as far as they are whole.

An MCAP file (https://mcap.dev/spec) is a sequence of records: a data section (schemas,
channels, messages, usually packed into chunks) and a summary with a footer at the end. A
recorder that loses power leaves a file without its summary and footer, cut inside a record.
This reader does not need them: it walks the data section from its start, so a cut log gives
every message before the cut (the whole records of a cut chunk too), and :meth:`McapLog.messages`
warns naming the byte where the log ends and the log time of its last message.

A chunk carries a CRC32 of its records (when its writer computed one; a CRC of 0 means none). A
chunk whose CRC does not match, that does not decompress, or whose records do not parse is
skipped with a warning, never used: its messages are given as :class:`LostMessage` (their log
times from the message index that follows the chunk, or the chunk's time span when there is
none), so that a frame source can mark their frames unreadable. A record whose length cannot be
true (past the end of the file, or an opcode MCAP does not define) is damage too: reading
resumes at the next whole chunk, or ends there when there is none.

Messages are deserialised with rosbags' type system from the log's own schemas (ROS 2
``ros2msg`` / ``ros2idl`` with CDR messages, ROS 1 ``ros1msg``); a log without schemas uses
ROS 2 Humble's types.

Convention: log times in integer nanoseconds; byte offsets from the start of the file.
"""

from __future__ import annotations

import logging
import struct
import zlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from slopedist.core.errors import InputFileError, OptionalDependencyError

_log = logging.getLogger(__name__)

MAGIC = b"\x89MCAP0\r\n"
"""The 8 bytes an MCAP file starts and ends with."""

OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX = range(1, 8)
OP_STATISTICS, OP_DATA_END = 0x0B, 0x0F
_SUMMARY_OPS = (OP_SCHEMA, OP_CHANNEL, OP_STATISTICS)
"""Summary records read for the channels and message counts of a whole file."""

RECORD_HEADER = struct.Struct("<BQ")
CHUNK_HEAD = struct.Struct("<QQQI")
MESSAGE_HEAD = struct.Struct("<HIQQ")
FOOTER_SIZE = 9 + 20 + len(MAGIC)
"""A footer record (opcode, length, two offsets, a CRC) and the closing magic, bytes."""

COMPRESSIONS = ("", "lz4", "zstd")
"""Chunk compressions MCAP defines."""

SEARCH_BLOCK = 1 << 20
"""Bytes read at a time while looking for the next whole chunk after damage."""


class McapError(ValueError):
    """A message that does not deserialise, or a file that is not a readable MCAP."""


@dataclass(frozen=True)
class McapConnection:
    """One channel of the log: what slopedist reads of it (as rosbags' ``Connection``)."""

    id: int
    topic: str
    msgtype: str
    msgcount: int
    encoding: str
    """Message encoding: ``cdr`` (ROS 2) or ``ros1``."""


class LostMessage(NamedTuple):
    """Given in place of a message's bytes: it was in a damaged chunk (``why``). With
    ``until_ns`` the chunk had no message index: its messages of any channel lay somewhere
    between the log time given with it and ``until_ns``, how many is unknown."""

    why: str
    until_ns: int | None = None


@dataclass
class _Schema:
    name: str
    encoding: str
    text: str


@dataclass
class _Damage:
    """A damaged chunk waiting for the message index records that follow it."""

    offset: int
    start_ns: int
    end_ns: int
    why: str
    entries: list[tuple[int, int]] = field(default_factory=list)
    """``(channel id, log time)`` of its messages, from the message index."""


Event = tuple[Any, ...]
"""What the walk over a file's records gives (see :meth:`_Walk.events`)."""


def _zstd() -> Any:
    try:
        from compression import zstd  # Python ≥ 3.14
    except ImportError:
        try:
            from backports import zstd  # rosbags' own
        except ImportError:
            import zstandard as zstd
    return zstd


def _decompress(compression: str, data: bytes, whole: bool) -> bytes:
    """A chunk's records; ``whole`` False: a cut chunk, decompressed as far as it goes."""
    if compression == "":
        return data
    try:
        if compression == "lz4":
            import lz4.frame

            if whole:
                return bytes(lz4.frame.decompress(data))
            return bytes(lz4.frame.LZ4FrameDecompressor().decompress(data))
        zstd = _zstd()
        if whole:
            return bytes(zstd.decompress(data))
        decompressor = zstd.ZstdDecompressor()
        stream = getattr(decompressor, "decompressobj", lambda: decompressor)()
        return bytes(stream.decompress(data))
    except ImportError as exc:
        raise OptionalDependencyError(compression, "rosbag", "reading MCAP chunks") from exc


def _string(data: bytes, at: int) -> tuple[str, int]:
    (n,) = struct.unpack_from("<I", data, at)
    end = at + 4 + n
    if end > len(data):
        raise McapError("a string runs past its record")
    return data[at + 4 : end].decode("utf-8"), end


def _parse_schema(body: bytes) -> tuple[int, _Schema]:
    (sid,) = struct.unpack_from("<H", body, 0)
    name, at = _string(body, 2)
    encoding, at = _string(body, at)
    (n,) = struct.unpack_from("<I", body, at)
    return sid, _Schema(name, encoding, body[at + 4 : at + 4 + n].decode("utf-8"))


def _parse_channel(body: bytes) -> tuple[int, int, str, str]:
    cid, sid = struct.unpack_from("<HH", body, 0)
    topic, at = _string(body, 4)
    encoding, _ = _string(body, at)
    return cid, sid, topic, encoding


def _inner_records(raw: bytes, whole: bool) -> Iterator[tuple[int, bytes]]:
    """``(opcode, body)`` of a chunk's records; a cut chunk (``whole`` False) ends at its last
    whole record, a whole one must parse to its end (else :class:`McapError`)."""
    at = 0
    while at < len(raw):
        if at + 9 > len(raw):
            if whole:
                raise McapError("its records do not parse")
            return
        op, length = RECORD_HEADER.unpack_from(raw, at)
        end = at + 9 + length
        if end > len(raw) or op == 0:
            if whole:
                raise McapError("its records do not parse")
            return
        yield op, raw[at + 9 : end]
        at = end


class _Walk:
    """One pass over the records of an open MCAP file (see the module docstring)."""

    def __init__(self, fh: Any, size: int) -> None:
        self.fh = fh
        self.size = size

    def _read(self, offset: int, n: int) -> bytes:
        self.fh.seek(offset)
        return bytes(self.fh.read(n))

    def events(self) -> Iterator[Event]:
        """``("schema", id, _Schema)``, ``("channel", id, schema id, topic, encoding)``,
        ``("message", channel id, log ns, bytes)``, ``("lost", channel id, log ns,
        LostMessage)``, ``("damage", text)``, and last ``("end", text)`` (text "" for a whole
        data section, else where and how the file ends)."""
        pos, pending = len(MAGIC), None
        while True:
            head = self._read(pos, 9) if pos + 9 <= self.size else b""
            op, length = RECORD_HEADER.unpack(head) if head else (None, 0)
            end = pos + 9 + length
            if op is None or op == 0 or 0x0F < op < 0x80 or end > self.size:
                yield from self._flush(pending)
                pending = None
                next_chunk = self._next_chunk(pos + 1) if op is not None else None
                if next_chunk is None:
                    yield from self._cut(pos, op, end)
                    return
                why = f"bytes {pos} to {next_chunk} do not hold whole MCAP records (damaged)"
                yield ("damage", f"{why}: read on from the chunk at byte {next_chunk}")
                pos = next_chunk
                continue
            if op == OP_MESSAGE_INDEX and pending is not None:
                pending.entries.extend(_index_entries(self._read(pos + 9, length)))
                pos = end
                continue
            yield from self._flush(pending)
            pending = None
            if op in (OP_DATA_END, OP_FOOTER):
                yield ("end", "")
                return
            if op == OP_CHUNK:
                chunk = self._chunk(pos, self._read(pos + 9, length), whole=True)
                if isinstance(chunk, _Damage):
                    pending = chunk
                else:
                    yield from chunk
            elif op in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
                yield from _record_events(op, self._read(pos + 9, length))
            pos = end

    def _cut(self, pos: int, op: int | None, end: int) -> Iterator[Event]:
        """The events of a file that ends at ``pos`` (a cut chunk's whole records first)."""
        if op == OP_CHUNK and end > self.size:
            salvaged = self._chunk(pos, self._read(pos + 9, self.size - pos - 9), whole=False)
            if not isinstance(salvaged, _Damage):
                yield from salvaged
        kind = {OP_CHUNK: "a chunk", OP_MESSAGE: "a message"}.get(op or -1, "a record")
        if op is None:
            where = f"the log ends at byte {pos} without its summary and footer"
        elif 0 < op <= 0x0F or op >= 0x80:
            where = f"the log ends at byte {self.size}, inside {kind} that starts at byte {pos}"
        else:
            where = f"the bytes from {pos} on are not MCAP records (damaged?)"
        yield ("end", where)

    def _flush(self, pending: _Damage | None) -> Iterator[Event]:
        """A damaged chunk's warning, then its lost messages (once its index is read)."""
        if pending is None:
            return
        known = pending.start_ns <= pending.end_ns
        entries = [e for e in pending.entries if pending.start_ns <= e[1] <= pending.end_ns]
        span = f" (log times {_stamp(pending.start_ns)} to {_stamp(pending.end_ns)})"
        lost = f"its {len(entries)} messages are lost" if entries else "its messages are lost"
        yield ("damage", f"{pending.why}{span if known else ''}: {lost}")
        if known and not entries:
            yield ("lost", None, pending.start_ns, LostMessage(pending.why, pending.end_ns))
        for channel, log_ns in sorted(entries, key=lambda e: e[1]):
            yield ("lost", channel, log_ns, LostMessage(pending.why))

    def _chunk(self, pos: int, body: bytes, whole: bool) -> list[Event] | _Damage:
        """The events of a chunk's records, or the damage that rules it out."""
        try:
            start_ns, end_ns, usize, crc = CHUNK_HEAD.unpack_from(body, 0)
            compression, at = _string(body, CHUNK_HEAD.size)
            (n,) = struct.unpack_from("<Q", body, at)
        except (struct.error, McapError, UnicodeDecodeError):
            return _Damage(pos, 0, -1, f"the chunk at byte {pos}: its header does not parse")
        what = f"the chunk at byte {pos}"
        if compression not in COMPRESSIONS:
            return _Damage(pos, start_ns, end_ns, f"{what}: unknown compression {compression!r}")
        data = body[at + 8 : at + 8 + n]
        try:
            raw = _decompress(compression, data, whole and len(data) == n)
        except OptionalDependencyError:
            raise
        except Exception:  # each decompressor has its own errors: the chunk is damaged
            return _Damage(pos, start_ns, end_ns, f"{what}: it does not decompress")
        if whole and len(raw) != usize:
            return _Damage(pos, start_ns, end_ns, f"{what}: {len(raw)} bytes, not {usize}")
        if whole and crc and zlib.crc32(raw) != crc:
            why = f"{what}: its CRC does not match its content"
            return _Damage(pos, start_ns, end_ns, why)
        try:
            events = [e for op, rec in _inner_records(raw, whole) for e in _record_events(op, rec)]
        except (McapError, struct.error, UnicodeDecodeError):
            return _Damage(pos, start_ns, end_ns, f"{what}: its records do not parse")
        messages = sorted((e for e in events if e[0] == "message"), key=lambda e: int(e[2]))
        return [e for e in events if e[0] != "message"] + messages

    def _next_chunk(self, start: int) -> int | None:
        """The offset of the first whole chunk record at or after ``start`` (one whose header
        fields agree with its length), or None."""
        at = start
        while at < self.size:
            block = self._read(at, SEARCH_BLOCK + 64)
            i = block.find(bytes([OP_CHUNK]))
            while 0 <= i < SEARCH_BLOCK:
                if self._is_chunk(at + i):
                    return at + i
                i = block.find(bytes([OP_CHUNK]), i + 1)
            at += SEARCH_BLOCK
        return None

    def _is_chunk(self, pos: int) -> bool:
        head = self._read(pos, 9 + CHUNK_HEAD.size + 4 + 4 + 8)
        if len(head) < 9 + CHUNK_HEAD.size + 4:
            return False
        _, length = RECORD_HEADER.unpack_from(head, 0)
        start_ns, end_ns, _, _ = CHUNK_HEAD.unpack_from(head, 9)
        (n_comp,) = struct.unpack_from("<I", head, 9 + CHUNK_HEAD.size)
        if n_comp > 4 or start_ns > end_ns or pos + 9 + length > self.size:
            return False
        at = 9 + CHUNK_HEAD.size + 4
        tail = self._read(pos + at, n_comp + 8)
        if len(tail) < n_comp + 8 or tail[:n_comp].decode("latin-1") not in COMPRESSIONS:
            return False
        (n,) = struct.unpack_from("<Q", tail, n_comp)
        return bool(CHUNK_HEAD.size + 4 + n_comp + 8 + n == length)


def _record_events(op: int, body: bytes) -> list[Event]:
    """The event of one schema, channel or message record (others give none)."""
    if op == OP_SCHEMA:
        return [("schema", *_parse_schema(body))]
    if op == OP_CHANNEL:
        return [("channel", *_parse_channel(body))]
    if op == OP_MESSAGE:
        if len(body) < MESSAGE_HEAD.size:
            raise McapError("a message record is too short")
        cid, _, log_ns, _ = MESSAGE_HEAD.unpack_from(body, 0)
        return [("message", cid, log_ns, body[MESSAGE_HEAD.size :])]
    return []


def _index_entries(body: bytes) -> list[tuple[int, int]]:
    """``(channel id, log time)`` of a message index record (none when it does not parse)."""
    try:
        (cid,) = struct.unpack_from("<H", body, 0)
        (n,) = struct.unpack_from("<I", body, 2)
        pairs = struct.iter_unpack("<QQ", body[6 : 6 + n - n % 16])
        return [(cid, int(log_ns)) for log_ns, _ in pairs]
    except struct.error:
        return []


_WARNED: set[tuple[str, int, int, str]] = set()
"""Warnings given already (file, size, modification time, text): one log is read several
times by a run (camera_info, frames, rotations), and says what is wrong with it once."""


def _warn_once(path: Path, text: str) -> None:
    stat = path.stat()
    key = (str(path), stat.st_size, stat.st_mtime_ns, text)
    if key not in _WARNED:
        _WARNED.add(key)
        _log.warning("warning: %s: %s", path, text)


class McapLog:
    """An MCAP file read as far as it is whole (see the module docstring), with the part of
    ``rosbags.highlevel.AnyReader``'s interface slopedist uses: :attr:`connections`,
    :meth:`messages`, :meth:`deserialize`.

    Raises (on :meth:`open`):
        InputFileError: the file is not an MCAP file (no magic), or holds no channel.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.connections: list[McapConnection] = []
        self.end = ""
        """Where and how the data section ends when it is not whole (found by :meth:`open`
        when the file has no usable summary), else ""."""
        self._fh: Any = None
        self._typestore: Any = None
        self._ros1_types: set[str] = set()
        self._size = 0

    def __enter__(self) -> McapLog:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def open(self) -> None:
        """Read the channels, their message types and counts (from the summary when the file
        is whole, else from one pass over its records)."""
        self._fh = self.path.open("rb")
        self._size = self.path.stat().st_size
        if self._fh.read(len(MAGIC)) != MAGIC:
            self.close()
            raise InputFileError(self.path, "not an MCAP file (it does not start with its magic)")
        schemas: dict[int, _Schema] = {}
        channels: dict[int, tuple[int, str, str]] = {}
        counts = self._read_summary(schemas, channels)
        if counts is None:
            counts = self._scan(schemas, channels)
        self.connections = [
            McapConnection(cid, topic, _msgtype(schemas, sid, topic), counts.get(cid, 0), enc)
            for cid, (sid, topic, enc) in sorted(channels.items())
        ]
        self._typestore = _typestore(schemas.values())
        self._ros1_types = {c.msgtype for c in self.connections if c.encoding == "ros1"}

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def _read_summary(
        self, schemas: dict[int, _Schema], channels: dict[int, tuple[int, str, str]]
    ) -> dict[int, int] | None:
        """Channels and counts from a whole file's summary, or None (no usable summary)."""
        if self._size < len(MAGIC) + FOOTER_SIZE:
            return None
        tail = _Walk(self._fh, self._size)._read(self._size - FOOTER_SIZE, FOOTER_SIZE)
        op, length = RECORD_HEADER.unpack_from(tail, 0)
        if tail[-len(MAGIC) :] != MAGIC or op != OP_FOOTER or length != 20:
            return None
        summary_start, _, summary_crc = struct.unpack_from("<QQI", tail, 9)
        footer_at = self._size - FOOTER_SIZE
        if not len(MAGIC) < summary_start <= footer_at:
            return None
        summary = _Walk(self._fh, self._size)._read(summary_start, footer_at - summary_start)
        if summary_crc and zlib.crc32(tail[:25], zlib.crc32(summary)) != summary_crc:
            return None
        counts: dict[int, int] | None = None
        try:
            for op, body in _inner_records(summary, whole=True):
                if op == OP_STATISTICS:
                    counts = _statistics_counts(body)
                elif op in _SUMMARY_OPS:
                    _keep(_record_events(op, body), schemas, channels)
        except (McapError, struct.error, UnicodeDecodeError):
            return None
        return counts

    def _scan(
        self, schemas: dict[int, _Schema], channels: dict[int, tuple[int, str, str]]
    ) -> dict[int, int]:
        """Channels and counts from one pass over the records (a file without summary)."""
        counts: dict[int, int] = {}
        for event in _Walk(self._fh, self._size).events():
            _keep([event], schemas, channels)
            if event[0] in ("message", "lost") and event[1] is not None:
                counts[event[1]] = counts.get(event[1], 0) + 1
            elif event[0] == "end":
                self.end = event[1]
        return counts

    def messages(
        self, connections: Iterable[McapConnection] | None = None
    ) -> Iterator[tuple[McapConnection, int, bytes | LostMessage]]:
        """``(connection, log time ns, bytes or LostMessage)`` of ``connections`` (None: all)
        in file order (a chunk's messages by log time), warning once of each damaged chunk
        and of a log that is cut short (see the module docstring). A chunk lost without a
        message index is given once per connection with its first log time and
        ``LostMessage.until_ns``."""
        wanted = {c.id: c for c in (self.connections if connections is None else connections)}
        last_ns: int | None = None
        count = 0
        for event in _Walk(self._fh, self._size).events():
            kind = event[0]
            if kind == "message":
                last_ns, count = event[2], count + 1
                if event[1] in wanted:
                    yield wanted[event[1]], event[2], event[3]
            elif kind == "lost":
                for conn in wanted.values() if event[1] is None else [wanted.get(event[1])]:
                    if conn is not None:
                        yield conn, event[2], event[3]
            elif kind == "damage":
                _warn_once(self.path, f"skipped a damaged part of the log: {event[1]}")
            elif kind == "end" and event[1]:
                after = "" if last_ns is None else f", the last at log time {_stamp(last_ns)}"
                _warn_once(self.path, f"{event[1]}: read its {count} messages before it{after}")

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        """One message of type ``msgtype`` from its bytes (CDR, or ROS 1 for ROS 1 types).

        Raises:
            McapError: it does not deserialise.
        """
        store = self._typestore
        read = store.deserialize_ros1 if msgtype in self._ros1_types else store.deserialize_cdr
        try:
            return read(raw, msgtype)
        except Exception as exc:  # rosbags' SerdeError, struct and index errors of bad bytes
            raise McapError(f"{type(exc).__name__}: {exc}") from None


def _stamp(ns: int) -> str:
    return f"{ns // 10**9}.{ns % 10**9:09d} s"


def _keep(
    events: list[Event], schemas: dict[int, _Schema], channels: dict[int, tuple[int, str, str]]
) -> None:
    for event in events:
        if event[0] == "schema":
            schemas[event[1]] = event[2]
        elif event[0] == "channel":
            channels[event[1]] = (event[2], event[3], event[4])


def _statistics_counts(body: bytes) -> dict[int, int]:
    """Per-channel message counts of a statistics record."""
    at = 8 + 2 + 4 + 4 + 4 + 4 + 8 + 8
    (n,) = struct.unpack_from("<I", body, at)
    pairs = struct.iter_unpack("<HQ", body[at + 4 : at + 4 + n - n % 10])
    return {int(cid): int(count) for cid, count in pairs}


def _msgtype(schemas: dict[int, _Schema], schema_id: int, topic: str) -> str:
    schema = schemas.get(schema_id)
    return schema.name if schema is not None else f"unknown type of {topic}"


def _typestore(schemas: Iterable[_Schema]) -> Any:
    """rosbags' types of the log's schemas (ROS 2 Humble's when it has none)."""
    try:
        from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
    except ImportError as exc:
        raise OptionalDependencyError("rosbags", "rosbag", "reading MCAP logs") from exc
    types: dict[str, Any] = {}
    for schema in schemas:
        try:
            if schema.encoding in ("ros2msg", "ros1msg"):
                types.update(get_types_from_msg(schema.text, schema.name))
            elif schema.encoding in ("ros2idl", "omgidl"):
                types.update(_idl_types(schema.text, get_types_from_idl))
        except Exception as exc:  # rosbags' TypesysError of a definition it cannot parse
            raise McapError(f"schema {schema.name} does not parse: {exc}") from None
    store = get_typestore(Stores.ROS2_HUMBLE)
    if types:
        store.register(types)
    return store


def _idl_types(text: str, parse: Callable[[str], dict[str, Any]]) -> dict[str, Any]:
    """The types of an IDL schema (rosbag2 writes several, each after an ``IDL:`` line)."""
    sep = "=" * 80 + "\n"
    if not text.startswith(f"{sep}IDL: "):
        return parse(text)
    types: dict[str, Any] = {}
    for part in text.split(sep)[1:]:
        types.update(parse(part.split("\n", 1)[1]))
    return types
