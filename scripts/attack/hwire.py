"""huddle's wire format, written from its docs (comms/src/wire/mod.rs), not its code.

Frames: "HD", version, flags, team, sender, incarnation (u64 LE), stamp (u32 LE),
[echo: target u8, seq16 u16 LE, hold u16 LE], body, [16-byte HMAC-SHA256 tag].
Body (format 4): seq varint, then items, each type varint, length varint, fields.
Body (format 3): seq varint, item count varint, then items as type and fields.
A varint is one byte below 251, else 251/252/253 and the value as u16/u32/u64 LE.
"""

import hashlib
import hmac
import struct

MAGIC = b"HD"
VERSION = 4
LEGACY_VERSION = 3
FLAG_TAGGED = 1
FLAG_ECHO = 2
TAG_LEN = 16
HEADER_LEN = 18

ITEM_UPDATE, ITEM_TALK, ITEM_TALK_HEAD, ITEM_NACK, ITEM_KNOWN = 0, 1, 2, 3, 4
# The team layer's table (team/src/lib.rs registers it; item 4 indexes it).
KNOWN_PATHS = ["machine.heuristic", "world.local", "machine.pass_to", "audio.heard"]


def varint(v):
    if v < 0:
        raise ValueError("varints are unsigned")
    if v <= 250:
        return bytes([v])
    if v < 1 << 16:
        return b"\xfb" + struct.pack("<H", v)
    if v < 1 << 32:
        return b"\xfc" + struct.pack("<I", v)
    return b"\xfd" + struct.pack("<Q", v)


def zigzag(v):
    return (v << 1) if v >= 0 else ((-v - 1) << 1) | 1


def string(s):
    b = s.encode() if isinstance(s, str) else s
    return varint(len(b)) + b


# Values: (tag, python value). Tags: 0 Int, 1 Float, 2 Bool, 3 String, 4 Floats, 5 Bytes.
def value(v):
    if isinstance(v, bool):
        return b"\x02" + bytes([1 if v else 0])
    if isinstance(v, int):
        return b"\x00" + varint(zigzag(v))
    if isinstance(v, float):
        return b"\x01" + struct.pack("<d", v)
    if isinstance(v, str):
        return b"\x03" + string(v)
    if isinstance(v, list):
        return b"\x04" + varint(len(v)) + b"".join(struct.pack("<d", f) for f in v)
    if isinstance(v, (bytes, bytearray)):
        return b"\x05" + varint(len(v)) + bytes(v)
    raise TypeError(type(v))


def update_fields(path, v, version=1, age_us=0):
    return string(path) + value(v) + varint(version) + varint(age_us)


def known_fields(index, v, version=1, age_us=0):
    return varint(index) + value(v) + varint(version) + varint(age_us)


def talk_fields(queue, seq, v):
    return string(queue) + varint(seq) + value(v)


def head_fields(queue, first, last):
    return string(queue) + varint(first) + varint(last)


def nack_fields(target, queue, first, last):
    return bytes([target]) + string(queue) + varint(first) + varint(last)


def item4(ty, fields):
    """A format 4 item: type, length, fields."""
    return varint(ty) + varint(len(fields)) + fields


def header(version, flags, team, sender, incarnation, stamp=0, echo=None):
    h = MAGIC + bytes([version, flags, team, sender])
    h += struct.pack("<QI", incarnation, stamp)
    if echo is not None:
        target, seq16, hold = echo
        h += bytes([target]) + struct.pack("<HH", seq16, hold)
    return h


def frame(team, sender, incarnation, seq, items, key=None, stamp=0, echo=None,
          version=VERSION, count=None):
    """A whole frame. `items` are already encoded (item4 for format 4; type + fields
    for format 3, where `count` defaults to their number)."""
    flags = (FLAG_TAGGED if key is not None else 0) | (FLAG_ECHO if echo else 0)
    body = varint(seq)
    if version == LEGACY_VERSION:
        body += varint(len(items) if count is None else count)
    body += b"".join(items)
    b = header(version, flags, team, sender, incarnation, stamp, echo) + body
    if key is not None:
        b += tag(key, b)
    return b


def tag(key, signed):
    return hmac.new(key, signed, hashlib.sha256).digest()[:TAG_LEN]


def update(path, v, version=1, age_us=0):
    return item4(ITEM_UPDATE, update_fields(path, v, version, age_us))
