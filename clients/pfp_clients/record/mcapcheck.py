"""A recording's bounds, checked from its record headers before one byte of it is decompressed.

``check_record`` walks the file's MCAP records in order (opcode, length, and for a
chunk its header and the first bytes of its compressed frame) and refuses, naming
the file and the limit of ``pfp_service.bounds.LIMITS``:

* a record whose length runs past the end of the file (a chunk declaring 2^62 bytes);
* a chunk larger than ``mcap_chunk_bytes``, compressed or declared uncompressed;
* a chunk declaring more than ``mcap_ratio`` times its compressed size (a decompression bomb:
  a few KB of zstd holding millions of messages), or a frame that itself declares more than
  its chunk does (what zstd and lz4 would then allocate);
* all chunks together declaring more than ``mcap_decoded_bytes``.

The reader then reads sequentially what was checked (``mcapfile.read_record``), never through
the summary's offsets, which were not; it counts messages against ``mcap_messages`` itself.
"""

from __future__ import annotations

import struct
from typing import IO

from pfp_service.bounds import limit
from pfp_service.errors import InputError

__all__ = ["MAGIC", "check_record"]

MAGIC = b"\x89MCAP0\r\n"
_CHUNK = 0x06
_FOOTER = 0x02
_LZ4_MAGIC = b"\x04\x22\x4d\x18"
_ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"


def check_record(f: IO[bytes], size: int, name: str) -> int:
    """Walk the records of the MCAP file ``f`` (``size`` bytes); returns the declared decoded bytes.

    Raises:
        InputError: naming ``name`` and the limit passed, or what is malformed.
    """
    chunk_most, ratio, decoded_most = (
        limit(n) for n in ("mcap_chunk_bytes", "mcap_ratio", "mcap_decoded_bytes")
    )
    f.seek(0)
    if f.read(len(MAGIC)) != MAGIC:
        raise InputError(name, "not a readable mission record: not MCAP (no magic)")
    pos, decoded, n = len(MAGIC), 0, 0
    while pos < size:
        head = f.read(9)
        if len(head) < 9:
            raise InputError(name, f"not a readable mission record: cut short at byte {pos:,}")
        opcode, length = struct.unpack("<BQ", head)
        pos += 9
        if length > size - pos:
            raise InputError(
                name,
                f"record {n} at byte {pos - 9:,} declares {length:,} bytes; the file has {size - pos:,} left",
            )
        if opcode == _CHUNK:
            decoded += _check_chunk(f, length, name, n, chunk_most, ratio)
            if decoded > decoded_most:
                raise InputError(
                    name, f"chunks declare more than {decoded_most:,} bytes decoded (mcap_decoded_bytes)"
                )
        pos += length
        f.seek(pos)
        n += 1
        if opcode == _FOOTER:
            break
    return decoded


def _check_chunk(f: IO[bytes], length: int, name: str, n: int, chunk_most: int, ratio: int) -> int:
    """One chunk's header and its frame's own declared size; returns the chunk's declared decoded size."""
    fixed = f.read(32)
    if len(fixed) < 32 or length < 32:
        raise InputError(name, f"chunk (record {n}) is cut short")
    _start, _end, declared, _crc, clen = struct.unpack("<QQQII", fixed)
    if 40 + clen > length:
        raise InputError(name, f"chunk (record {n}) is malformed: its compression name runs past it")
    compression = f.read(clen).decode("ascii", "replace")
    (stored,) = struct.unpack("<Q", f.read(8))
    if stored > length - 40 - clen:
        raise InputError(
            name, f"chunk (record {n}) declares {stored:,} bytes of records; it holds {length - 40 - clen:,}"
        )
    if max(declared, stored) > chunk_most:
        raise InputError(
            name,
            f"chunk (record {n}) declares {max(declared, stored):,} bytes; the limit is {chunk_most:,} (mcap_chunk_bytes)",
        )
    if compression == "":
        if declared != stored:
            raise InputError(
                name, f"chunk (record {n}) is uncompressed but declares {declared:,} bytes for {stored:,}"
            )
        return declared
    if declared > max(stored * ratio, 64 * 1024):
        raise InputError(
            name,
            f"chunk (record {n}) declares {declared:,} bytes from {stored:,} compressed; "
            f"more than {ratio} times (mcap_ratio)",
        )
    frame = f.read(min(stored, 32))
    framed = _frame_size(compression, frame)
    if framed is None or framed > declared:
        raise InputError(
            name,
            f"chunk (record {n}): its {compression or 'unknown'} frame declares "
            f"{'no size' if framed is None else f'{framed:,} bytes'} against the chunk's {declared:,}",
        )
    return declared


def _frame_size(compression: str, frame: bytes) -> int | None:
    """What a chunk's compressed frame says it decompresses to; zstd without a size gets the chunk's cap."""
    if compression == "zstd" and frame.startswith(_ZSTD_MAGIC):
        import zstandard

        try:
            size = zstandard.frame_content_size(frame)
        except zstandard.ZstdError:
            return None
        return 0 if size == -1 else size  # unknown: mcap passes the declared size as zstd's output cap
    if compression == "lz4" and frame.startswith(_LZ4_MAGIC):
        try:
            import lz4.frame
        except ImportError:
            return None
        try:
            info = lz4.frame.get_frame_info(frame)
        except RuntimeError:
            return None
        size = int(info.get("content_size") or 0)
        return size if size > 0 else None  # lz4 decompresses without a cap: it must say its size
    return None
