"""Protobuf wire-format decoding, the little gpsdr needs of it.

Why hand-written: ``protobuf`` is not a dependency, and reading a handful of
scalar fields of one message type (MCAP ``foxglove.LocationFix`` channels) needs
only the wire format: a varint key (field number << 3 | wire type), then a
varint (type 0), 8 bytes (1), a varint length and the bytes (2) or 4 bytes (5).
Field numbers come from the channel's FileDescriptorSet (:func:`field_numbers`).
"""

from __future__ import annotations

from typing import Any


def varint(buf: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        b = buf[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, pos
        shift += 7
        if shift > 63:
            raise ValueError("varint longer than 10 bytes")


def fields(buf: bytes) -> list[tuple[int, int, Any]]:
    """Protobuf wire format: (field number, wire type, value) with value an int
    (varint), bytes (length-delimited, fixed64, fixed32)."""
    out: list[tuple[int, int, Any]] = []
    pos, end = 0, len(buf)
    while pos < end:
        key, pos = varint(buf, pos)
        num, wt = key >> 3, key & 7
        if wt == 0:
            value, pos = varint(buf, pos)
        elif wt in (1, 5):
            n = 8 if wt == 1 else 4
            if pos + n > end:
                raise ValueError("truncated fixed-width field")
            value, pos = buf[pos:pos + n], pos + n
        elif wt == 2:
            n, pos = varint(buf, pos)
            if pos + n > end:
                raise ValueError("truncated length-delimited field")
            value, pos = buf[pos:pos + n], pos + n
        else:
            raise ValueError(f"unsupported wire type {wt}")
        out.append((num, wt, value))
    return out


def field_numbers(descriptor_set: bytes, message: str, required: tuple[str, ...] = ()
                  ) -> dict[str, int] | None:
    """Field numbers by name of ``message`` in a FileDescriptorSet (the schema data of
    a protobuf MCAP channel): FileDescriptorSet.file = 1, FileDescriptorProto.message_type
    = 4, DescriptorProto.name = 1 / field = 2, FieldDescriptorProto.name = 1 / number = 3.
    None when the descriptor is unreadable or lacks the message or a ``required`` field."""
    try:
        for num, wt, file in fields(descriptor_set):
            if num != 1 or wt != 2:
                continue
            for n2, w2, msg in fields(file):
                if n2 != 4 or w2 != 2:
                    continue
                parts = fields(msg)
                if not any(n == 1 and v == message.encode() for n, _, v in parts):
                    continue
                numbers = {}
                for n3, w3, fdesc in parts:
                    if n3 == 2 and w3 == 2:
                        f = {n: v for n, _, v in fields(fdesc)}
                        if 1 in f and 3 in f:
                            numbers[bytes(f[1]).decode("utf-8", "replace")] = int(f[3])
                if set(required) <= numbers.keys():
                    return numbers
    except (ValueError, IndexError, TypeError):
        pass
    return None
