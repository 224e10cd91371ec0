"""The relay line protocol without I/O: value literals both ways, reply lines parsed.

Shared by the blocking :class:`~huddle_client.Relay` and the asyncio
:class:`~huddle_client.AsyncRelay`.
"""

from __future__ import annotations

import math
import numbers
import struct
import time
from dataclasses import dataclass, field, replace
from typing import Any, Dict, Iterator, List, Optional, Sequence, Union

#: A value as Python holds it: ``int`` (64-bit), ``float``, ``bool``, ``str``, ``bytes``
#: or a list of floats.
Value = Union[int, float, bool, str, bytes, List[float]]

#: Inputs :func:`encode_value` accepts (``bytearray``/``memoryview`` as bytes, tuples
#: and lists of numbers as a float list).
ValueLike = Union[Value, bytearray, memoryview, Sequence[Union[int, float]]]

I64_MIN = -(2**63)
I64_MAX = 2**63 - 1

#: Default relay port.
DEFAULT_PORT = 2001

#: Longest ``REFR`` period the relay takes, in milliseconds (one hour).
MAX_INTERVAL_MS = 3_600_000


class HuddleError(Exception):
    """Base of every error this package raises on its own."""


class RelayError(HuddleError):
    """The relay answered ``ERR code text``.

    ``code`` is the relay's stable numeric code (404 no value, 406 older than the
    ``max_age_ms`` asked for, 410 bad key, 411 bad pattern, 412 bad value, 413 bad
    period, 420 another robot's key, 421 wrong kind of key, 422 too large, 423 the
    daemon's own key, read-only (``local.var.team.*``, ``local.var.gc.*``,
    ``local.var.huddle.*``), 429 too many,
    430 the talk queue's retention is full, 503 not available, 400-403 malformed
    commands);
    ``text`` is the explanation, for people.
    """

    def __init__(self, code: int, text: str, command: str = "") -> None:
        self.code = code
        self.text = text
        self.command = command
        where = f" (to {command!r})" if command else ""
        super().__init__(f"ERR {code} {text}{where}")


class RelayConnectionError(HuddleError, ConnectionError):
    """The relay could not be reached, or closed the connection unexpectedly (and, with
    ``reconnect=True``, could not be reached again within the timeout)."""


class RelayTimeout(HuddleError, TimeoutError):
    """No answer (or no update, for a watch with a ``timeout``) within the time allowed.

    Also a built-in ``TimeoutError``, so ``except TimeoutError`` keeps working. A request
    that timed out closes its connection (a late answer would be taken for the next
    one's); with ``reconnect=True`` the next request opens a new one.
    """


class TalkLost(HuddleError):
    """Talk messages the daemon gave up on: they could not be recovered from the
    network, so the queue skips them. The relay reports this with a line starting with
    ``LOST``; a watch raises it (default) or yields it (``lost="event"``), never drops it.

    ``line`` is the relay's line as sent. ``queue`` is the queue it names (as the relay
    wrote it, e.g. ``3.talk.plan``), ``sender`` the robot that posted the messages, and
    ``first``/``last`` their sequence numbers (inclusive), where the line carries them
    (``None`` otherwise).
    """

    def __init__(
        self,
        line: str,
        queue: Optional[str],
        sender: Optional[int],
        first: Optional[int],
        last: Optional[int],
    ) -> None:
        self.line = line
        self.queue = queue
        self.sender = sender
        self.first = first
        self.last = last
        super().__init__(f"talk messages lost: {line}")

    @property
    def count(self) -> Optional[int]:
        """How many messages were lost, when the line says."""
        if self.first is None or self.last is None:
            return None
        return self.last - self.first + 1


@dataclass(frozen=True)
class Binding:
    """One value as the relay reported it.

    ``key`` is the key as stored (``3.var.ball.dist``, ``local.var.mode``; a ``*.var.x``
    read names the copy that answered), ``type`` the relay's type name (``int``,
    ``float``, ``bool``, ``string``, ``floats``, ``bytes``), ``value`` the Python value,
    ``age_ms`` the milliseconds since it was set, on the answering robot's clock, and
    ``owner`` the robot it belongs to (for ``local.`` keys, the robot of this relay), and
    ``departed`` whether the relay flags the owner as departed (silent for longer than
    the daemon's departure limit: the value is old news however young its age; relay
    protocol 2 and later). A talk message is a binding of a ``n.talk.queue`` key with
    age 0.
    """

    key: str
    type: str
    value: Value
    age_ms: int
    owner: int
    departed: bool = False
    #: ``time.monotonic()`` when this client read the line (for :attr:`age_now_ms`).
    received: float = field(default_factory=time.monotonic, compare=False, repr=False)

    @property
    def age_now_ms(self) -> int:
        """The age now: ``age_ms`` plus the time since this client read it. A binding
        kept by a program keeps getting older; ``age_ms`` is the age when it was read."""
        return self.age_ms + int((time.monotonic() - self.received) * 1000)

    def __array__(self, dtype: Any = None, copy: Any = None) -> Any:
        """``numpy.asarray(binding)`` is the value as an array (numpy is imported only
        when numpy itself asks)."""
        import numpy

        return numpy.asarray(self.value, dtype=dtype)

    @property
    def is_talk(self) -> bool:
        """Whether this is a talk message (``n.talk.queue``)."""
        return self.key.split(".")[1:2] == ["talk"]


def _is_control(ch: str) -> bool:
    o = ord(ch)
    return o < 0x20 or 0x7F <= o <= 0x9F


def _quote(s: str) -> str:
    try:
        s.encode("utf-8")
    except UnicodeEncodeError as e:
        raise ValueError(f"string is not valid Unicode text: {e}") from None
    out = ['"']
    for ch in s:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\r":
            out.append("\\r")
        elif ch == "\t":
            out.append("\\t")
        elif _is_control(ch):
            out.append("\\u{%x}" % ord(ch))
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _float_literal(x: float) -> str:
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    # repr is the shortest string that reads back to the same float.
    return repr(x)


def _exact_float(x: object, where: str) -> float:
    """A number as an f64, refusing anything that would change on the way."""
    if isinstance(x, bool) or _is_numpy_bool(x) or not isinstance(x, numbers.Real):
        raise TypeError(f"{where}: {type(x).__name__} is not a number")
    if isinstance(x, float):
        return float(x)  # numpy.float64 is a float whose repr is not a literal
    if isinstance(x, numbers.Integral):
        n = int(x)
        try:
            f = float(n)
        except OverflowError:
            raise ValueError(f"{where}: {n} does not fit in a 64-bit float") from None
        if int(f) != n:
            raise ValueError(f"{where}: {n} is not exactly representable as a 64-bit float")
        return f
    f = float(x)
    # Widening (numpy.float32) is exact; narrowing (Fraction(1, 3)) is refused.
    if not (f == x or (math.isnan(f) and x != x)):
        raise ValueError(f"{where}: {x!r} is not exactly representable as a 64-bit float")
    return f


def _is_numpy_bool(x: object) -> bool:
    # numpy.bool_ is neither a bool nor a number; known by its name, without numpy.
    return type(x).__name__ in ("bool_", "bool") and type(x) is not bool and hasattr(x, "item")


def plain_value(value: object) -> object:
    """``value`` with array-likes made plain Python, by duck typing (numpy is never
    imported): a 0-d array or numpy scalar (``.item()``) becomes its Python scalar,
    a 1-D array (``.tolist()``) a list; ``numpy.float64`` (a ``float`` subclass) a
    ``float``. A 2-D array raises ``ValueError``. Anything else is returned as it is."""
    if type(value) in (bool, int, float, str, bytes, list, tuple):
        return value
    if isinstance(value, (bytes, bytearray, memoryview)):
        return value
    if isinstance(value, bool):
        return bool(value)
    if _is_numpy_bool(value):
        return bool(value.item())  # type: ignore[attr-defined]
    ndim = getattr(value, "ndim", None)
    if isinstance(ndim, int) and not isinstance(ndim, bool):
        if ndim == 0 and hasattr(value, "item"):
            return plain_value(value.item())  # type: ignore[attr-defined]
        if ndim == 1 and hasattr(value, "tolist"):
            return value.tolist()  # type: ignore[attr-defined]
        if ndim > 1:
            shape = getattr(value, "shape", "?")
            raise ValueError(
                f"a {ndim}-D array (shape {shape}): the relay takes 1-D float lists; "
                "send .ravel() and the shape apart"
            )
    if isinstance(value, float):
        return float(value)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, str):
        return str(value)
    return value


def encode_value(value: object) -> str:
    """The relay literal for a Python value.

    ``bool`` → ``bool``; ``int`` → ``int`` (must fit in 64 bits); ``float`` → ``float``;
    ``str`` → ``string``; ``bytes``/``bytearray``/``memoryview`` → ``bytes``; a list or
    tuple of numbers → ``floats`` (64-bit; an int must be exactly representable).
    numpy values are taken by duck typing, without importing numpy: scalars
    (``float64``, ``float32``, ``int64``, ``bool_``) as their Python value and 1-D arrays
    as lists (see :func:`plain_value`); so are other array libraries' values with
    ``.item()``/``.tolist()`` and ``ndim``.
    Anything else raises ``TypeError``; a value that would change on the way raises
    ``ValueError``: nothing is narrowed silently.
    """
    value = plain_value(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        if not I64_MIN <= value <= I64_MAX:
            raise ValueError(f"{value} does not fit in a 64-bit integer")
        return str(value)
    if isinstance(value, float):
        return _float_literal(value)
    if isinstance(value, str):
        return _quote(value)
    if isinstance(value, (bytes, bytearray, memoryview)):
        return "0x" + bytes(value).hex()
    if isinstance(value, (list, tuple)):
        items = [_exact_float(x, f"element {i}") for i, x in enumerate(value)]
        return "[" + ", ".join(_float_literal(x) for x in items) + "]"
    if isinstance(value, numbers.Integral):  # numpy.int64 and friends
        return encode_value(int(value))
    if isinstance(value, numbers.Real):  # numpy.float32 and friends, exactly
        return _float_literal(_exact_float(value, "value"))
    raise TypeError(
        f"cannot send a {type(value).__name__}: the relay takes int, float, bool, str, "
        "bytes and lists of numbers"
    )


def _unquote(lit: str) -> str:
    if len(lit) < 2 or lit[0] != '"' or lit[-1] != '"':
        raise ValueError(f"bad string literal {lit!r}")
    out = []
    i, end = 1, len(lit) - 1
    simple = {'"': '"', "\\": "\\", "n": "\n", "r": "\r", "t": "\t"}
    while i < end:
        ch = lit[i]
        if ch != "\\":
            out.append(ch)
            i += 1
            continue
        esc = lit[i + 1]
        if esc in simple:
            out.append(simple[esc])
            i += 2
        elif esc == "u" and lit[i + 2] == "{":
            close = lit.index("}", i + 3)
            out.append(chr(int(lit[i + 3 : close], 16)))
            i = close + 1
        else:
            raise ValueError(f"bad escape in {lit!r}")
    return "".join(out)


def decode_value(type_name: str, literal: str) -> Value:
    """The Python value of a relay literal of type ``type_name``. A type this package
    does not know is returned as its literal text."""
    if type_name == "int":
        return int(literal)
    if type_name == "float":
        return float(literal)
    if type_name == "bool":
        return literal == "true"
    if type_name == "string":
        return _unquote(literal)
    if type_name == "floats":
        inner = literal.strip()[1:-1].strip()
        return [float(x) for x in inner.split(",")] if inner else []
    if type_name == "bytes":
        return bytes.fromhex(literal[2:])
    return literal


def parse_binding(line: str, robot: int) -> Optional[Binding]:
    """A ``VAL``/``UPD key type value age_ms [flag ...]`` line; ``None`` for any other
    line."""
    word, _, rest = line.partition(" ")
    if word not in ("VAL", "UPD"):
        return None
    try:
        key, type_name, rest = rest.split(" ", 2)
        flags = []
        # After the age (all digits) may come flag words (letters only): `departed`;
        # unknown flags are skipped, so newer relays stay readable.
        while True:
            literal, last = rest.rsplit(" ", 1)
            if last.isdigit():
                age = int(last)
                break
            if not (last.isascii() and last.isalpha()):
                return None
            flags.append(last)
            rest = literal
        head = key.split(".", 1)[0]
        owner = int(head) if head.isdigit() else robot
        value = decode_value(type_name, literal)
        return Binding(key, type_name, value, age, owner, "departed" in flags)
    except (ValueError, IndexError):
        return None


def parse_error(line: str, command: str = "") -> Optional[RelayError]:
    """An ``ERR code text`` line as a :class:`RelayError`; ``None`` for other lines."""
    if not line.startswith("ERR "):
        return None
    code, _, text = line[4:].partition(" ")
    try:
        number = int(code)
    except ValueError:
        number = 0
    return RelayError(number, text, command)


def parse_lost(line: str) -> Optional[TalkLost]:
    """A line starting with ``LOST`` as a :class:`TalkLost`; ``None`` for other lines.

    The fields are read leniently (``LOST 3.talk.plan 4 6``, ``LOST plan 3 4 6``): the
    first word that is not a number is the queue, the last two numbers are the first
    and last sequence numbers lost, and the sender is the queue key's robot or, failing
    that, a third number before them.
    """
    if not (line == "LOST" or line.startswith("LOST ")):
        return None
    queue: Optional[str] = None
    numbers_seen: List[int] = []
    for word in line.split()[1:]:
        if word.isdigit():
            numbers_seen.append(int(word))
        elif queue is None:
            queue = word
    sender: Optional[int] = None
    if queue is not None:
        head = queue.split(".", 1)[0]
        if head.isdigit() and ".talk." in queue:
            sender = int(head)
    first = last = None
    if len(numbers_seen) >= 2:
        first, last = numbers_seen[-2], numbers_seen[-1]
        if sender is None and len(numbers_seen) >= 3:
            sender = numbers_seen[-3]
    return TalkLost(line, queue, sender, first, last)


def parse_greeting(line: str) -> "tuple[int, int]":
    """``HUDDLE <version> robot <id>`` → (version, robot id)."""
    words = line.split()
    if len(words) != 4 or words[0] != "HUDDLE" or words[2] != "robot":
        raise RelayConnectionError(f"not a huddle relay: it said {line!r}")
    return int(words[1]), int(words[3])


def talk_key(queue: str) -> str:
    """``plan`` → ``*.talk.plan``; a full key (``*.talk.plan``) is kept."""
    return queue if "." in queue else f"*.talk.{queue}"


def check_interval(interval_ms: int) -> int:
    if isinstance(interval_ms, bool) or not isinstance(interval_ms, int):
        raise TypeError("interval_ms is whole milliseconds (an int)")
    if not 0 <= interval_ms <= MAX_INTERVAL_MS:
        raise ValueError(f"interval_ms must be within 0..={MAX_INTERVAL_MS}")
    return interval_ms


def check_patterns(pattern: Union[str, Sequence[str]]) -> List[str]:
    patterns = [pattern] if isinstance(pattern, str) else list(pattern)
    if not patterns:
        raise ValueError("watch needs at least one pattern")
    for p in patterns:
        if not isinstance(p, str) or not p or any(c.isspace() for c in p):
            raise ValueError(f"bad pattern {p!r}")
    return patterns


def check_word(what: str, text: str) -> str:
    """Keys and patterns are single words on the line."""
    if not isinstance(text, str) or not text or any(c.isspace() for c in text):
        raise ValueError(f"bad {what} {text!r}")
    return text


def getv_line(key: str, max_age_ms: Optional[int]) -> str:
    """``GETV key`` or ``GETV key max_age_ms``."""
    check_word("key", key)
    if max_age_ms is None:
        return f"GETV {key}"
    if isinstance(max_age_ms, bool) or not isinstance(max_age_ms, int) or max_age_ms < 0:
        raise ValueError("max_age_ms is whole milliseconds (an int >= 0)")
    return f"GETV {key} {max_age_ms}"


#: The local key a client writes once to learn whether the relay keeps float lists as
#: 64-bit floats (newer relays) or 32-bit ones (older relays), before it sends a list
#: that only 64 bits hold exactly.
FLOAT_PROBE_KEY = "local.var.huddle_client.float_probe"
FLOAT_PROBE = 16777217.0  # 2**24 + 1: a 32-bit float cannot hold it


def _f32_exact(x: float) -> bool:
    try:
        y: float = struct.unpack("<f", struct.pack("<f", x))[0]
    except OverflowError:
        return False
    return y == x or (math.isnan(x) and math.isnan(y))


def needs_wide_floats(value: object) -> bool:
    """Whether ``value`` is a float list that a 32-bit float list would change."""
    value = plain_value(value)
    if not isinstance(value, (list, tuple)):
        return False
    return not all(
        _f32_exact(_exact_float(x, f"element {i}")) for i, x in enumerate(value)
    )


def narrow_error(value: object) -> ValueError:
    return ValueError(
        f"{value!r}: this relay keeps float lists as 32-bit floats, which would change "
        "these values; send them one by one as floats, or scale them"
    )


@dataclass(frozen=True)
class Joined:
    """A watch event (``events=True``): robot ``robot``'s values started arriving: the
    first one this watch saw, or the first after it departed or restarted."""

    robot: int


@dataclass(frozen=True)
class Left:
    """A watch event (``events=True``): robot ``robot`` departed (silent for longer
    than the daemon's departure limit; its values come again flagged ``departed``) or
    its values were released. ``released`` tells which."""

    robot: int
    released: bool = False


@dataclass(frozen=True)
class Reconnected:
    """A watch event (``events=True``): the connection dropped (a daemon restart) and
    the watch connected and subscribed again; the current values follow. ``robot`` is
    the relay's robot id now."""

    robot: int


#: What a watch yields with ``events=True``, besides bindings.
Event = Union[Joined, Left, Reconnected]

#: How long a robot's values may stay unchanged on a push watch before the watch asks
#: the relay whether the robot is still there (milliseconds). The daemon flags a robot
#: departed after 300 ms of silence by default.
DEFAULT_PROBE_MS = 250

#: Reconnect backoff: first wait and longest wait between attempts, in seconds.
BACKOFF_FIRST_S = 0.05
BACKOFF_MAX_S = 1.0


def backoff_delays(first: float = BACKOFF_FIRST_S, most: float = BACKOFF_MAX_S) -> "Iterator[float]":
    """Waits between reconnect attempts: doubling from ``first`` up to ``most``."""
    wait = first
    while True:
        yield wait
        wait = min(wait * 2, most)


def robot_of(key: str) -> Optional[int]:
    """The robot a stored key belongs to (``3.var.x`` -> 3), ``None`` for ``local``."""
    head = key.split(".", 1)[0]
    return int(head) if head.isdigit() else None


class WatchBook:
    """What a watch knows about the values it delivered, without I/O: the newest
    binding of each key, which robots are present, and which quiet robots to ask about.

    A push watch (``interval_ms=0``) hears nothing when a robot dies: the relay pushes
    changes only. So when a robot's values have not changed for ``probe_ms``, the watch
    asks the relay (``GETV`` of that robot's newest key, on the watch's connection) and
    learns its true age and whether it departed; a departure re-delivers the robot's
    values flagged ``departed`` with their ages now, and a :class:`Left` event.
    """

    def __init__(self, probe_ms: Optional[int]) -> None:
        self.probe_ms = probe_ms
        self.latest: Dict[str, Binding] = {}
        self.departed: Dict[int, bool] = {}
        self.heard: Dict[int, float] = {}
        #: Keys asked about (``GETV``), in the order the answers come.
        self.probing: List[str] = []

    def take(self, b: Binding) -> List[Any]:
        """A pushed binding: the events it brings, then the binding."""
        if b.is_talk:
            return [b]
        out: List[Any] = []
        owner = robot_of(b.key)
        if owner is not None:
            was = self.departed.get(owner)
            if b.departed:
                if was is False:
                    out.append(Left(owner))
                self.departed[owner] = True
            else:
                if was is None or was:
                    out.append(Joined(owner))
                self.departed[owner] = False
                self.heard[owner] = b.received
        self.latest[b.key] = b
        out.append(b)
        return out

    def due(self, now: float) -> List[str]:
        """Keys to ask about now (one per quiet robot); none while answers are due."""
        if self.probe_ms is None or self.probing:
            return []
        keys = []
        for owner, departed in self.departed.items():
            if departed or (now - self.heard[owner]) * 1000 < self.probe_ms:
                continue
            mine = [b for k, b in self.latest.items() if robot_of(k) == owner]
            if mine:
                keys.append(max(mine, key=lambda b: b.received).key)
                self.heard[owner] = now
        self.probing = keys
        return keys

    def next_due(self) -> Optional[float]:
        """When :meth:`due` next has something (``time.monotonic()`` seconds)."""
        if self.probe_ms is None or self.probing:
            return None
        times = [t for o, t in self.heard.items() if not self.departed.get(o, True)]
        return min(times) + self.probe_ms / 1000 if times else None

    def answered(self, b: Optional[Binding], now: float) -> List[Any]:
        """The relay's answer to the oldest question (``None``: no value any more):
        what to deliver."""
        if not self.probing:
            return []
        key = self.probing.pop(0)
        owner = robot_of(key)
        if owner is None:
            return []
        was_present = self.departed.get(owner) is False
        if b is None:
            for k in [k for k in self.latest if robot_of(k) == owner]:
                del self.latest[k]
            self.departed[owner] = True
            return [Left(owner, released=True)] if was_present else []
        if not b.departed:
            self.heard[owner] = now
            self.latest[b.key] = b
            return []
        self.departed[owner] = True
        out: List[Any] = [Left(owner)] if was_present else []
        for k, old in sorted(self.latest.items()):
            if robot_of(k) != owner:
                continue
            fresh = b if k == b.key else replace(old, departed=True, age_ms=old.age_now_ms, received=now)
            self.latest[k] = fresh
            out.append(fresh)
        return out

    def snapshot(self) -> Dict[str, Binding]:
        """The newest binding of each key, its age brought up to now."""
        now = time.monotonic()
        return {k: replace(b, age_ms=b.age_now_ms, received=now) for k, b in sorted(self.latest.items())}


#: Internal keys that ``keys()`` leaves out unless asked (the daemon's counters, this
#: client's probe).
INTERNAL_PREFIXES = ("local.var.huddle.", "local.var.huddle_client.")


def is_internal(key: str) -> bool:
    return key.startswith(INTERNAL_PREFIXES)


#: Where the daemon keeps its counters.
STATS_PREFIX = "local.var.huddle.stats."

#: The lines a snapshot sends: watch, refresh (which pushes the current values once),
#: list the watches (its ``END`` marks the snapshot's end), forget the watches.
SNAPSHOT_PERIOD_MS = MAX_INTERVAL_MS


def snapshot_lines(patterns: List[str]) -> List[str]:
    return [f"ADDW {p}" for p in patterns] + [f"REFR {SNAPSHOT_PERIOD_MS}", "LSTW", "CLRW"]


class SnapshotReader:
    """Reads the answers to :func:`snapshot_lines`, line by line."""

    def __init__(self, robot: int) -> None:
        self.robot = robot
        self.bindings: Dict[str, Binding] = {}
        self.error: Optional[RelayError] = None
        self.ended = False
        self.done = False

    def feed(self, line: str) -> None:
        if self.ended:
            # The answer to CLRW.
            self.done = True
            return
        if line == "END":
            self.ended = True
            return
        if line.startswith("UPD "):
            b = parse_binding(line, self.robot)
            if b is not None and not b.is_talk:
                self.bindings[b.key] = b
            return
        err = parse_error(line)
        if err is not None and self.error is None:
            self.error = err
