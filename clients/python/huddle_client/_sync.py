"""The blocking client: :class:`Relay` and its :class:`Watch`."""

from __future__ import annotations

import socket
import threading
import time
from types import TracebackType
from typing import Iterator, List, Optional, Sequence, Type, TypeVar, Union, cast, overload

from ._protocol import (
    DEFAULT_PORT,
    Binding,
    RelayConnectionError,
    TalkLost,
    check_interval,
    check_patterns,
    FLOAT_PROBE,
    FLOAT_PROBE_KEY,
    check_word,
    narrow_error,
    needs_wide_floats,
    getv_line,
    encode_value,
    parse_binding,
    parse_error,
    parse_greeting,
    parse_lost,
    talk_key,
)

from typing import Literal

T = TypeVar("T")

#: The longest line read from the relay (values are far smaller; this bounds memory).
MAX_LINE = 16 << 20


class _Lines:
    """A TCP connection to a relay, read line by line with a timeout per read."""

    def __init__(self, host: str, port: int, timeout: Optional[float]) -> None:
        self.where = f"{host}:{port}"
        try:
            self.sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as e:
            raise RelayConnectionError(
                f"cannot reach a huddle relay at {self.where}: {e} (is the daemon running?)"
            ) from e
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buf = bytearray()
        self.closed = False
        self.version, self.robot = parse_greeting(self.readline(timeout))

    def send(self, line: str) -> None:
        try:
            self.sock.sendall(line.encode("utf-8") + b"\n")
        except OSError as e:
            self.close()
            raise RelayConnectionError(f"relay {self.where}: {e}") from e

    def readline(self, timeout: Optional[float]) -> str:
        """One line without its terminator; ``TimeoutError`` after ``timeout`` seconds
        (``None``: wait as long as it takes); ``RelayConnectionError`` on EOF."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            nl = self.buf.find(b"\n")
            if nl >= 0:
                raw = bytes(self.buf[:nl])
                del self.buf[: nl + 1]
                return raw.decode("utf-8", "replace").rstrip("\r")
            if len(self.buf) > MAX_LINE:
                self.close()
                raise RelayConnectionError(f"relay {self.where}: line too long")
            if self.closed:
                raise RelayConnectionError(f"relay {self.where}: connection closed")
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise TimeoutError(f"relay {self.where}: no answer within {timeout} s")
            self.sock.settimeout(left)
            try:
                chunk = self.sock.recv(65536)
            except socket.timeout:
                raise TimeoutError(f"relay {self.where}: no answer within {timeout} s") from None
            except OSError as e:
                self.close()
                raise RelayConnectionError(f"relay {self.where}: {e}") from e
            if not chunk:
                self.close()
                raise RelayConnectionError(f"relay {self.where} closed the connection")
            self.buf += chunk

    def quit(self, timeout: float) -> None:
        """``QUIT``, read up to ``BYE`` (briefly), close."""
        if self.closed:
            return
        try:
            self.send("QUIT")
            end = time.monotonic() + timeout
            while time.monotonic() < end:
                if self.readline(max(end - time.monotonic(), 0.001)) == "BYE":
                    break
        except (OSError, TimeoutError, RelayConnectionError):
            pass
        self.close()

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            try:
                self.sock.close()
            except OSError:  # pragma: no cover
                pass


class Relay:
    """A connection to a huddle daemon's relay (``huddle daemon``, TCP port 2001).

    Use it as a context manager; every method is blocking and thread-safe::

        with Relay("127.0.0.1", 2001) as relay:
            relay.set("*.var.ball.dist", 1.5)

    ``timeout`` (seconds) bounds connecting and each answer; a timed-out connection is
    closed (its answer could arrive later and be taken for the next one's).
    """

    def __init__(
        self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, timeout: Optional[float] = 5.0
    ) -> None:
        self.host = host
        self.port = port
        self.timeout = timeout
        self._lines = _Lines(host, port, timeout)
        self._lock = threading.Lock()
        self._wide: Optional[bool] = None
        self._watches: List[Watch] = []  # type: ignore[type-arg]
        #: The relay protocol version from the greeting.
        self.version: int = self._lines.version
        #: The id of the robot this relay belongs to.
        self.robot: int = self._lines.robot

    def __enter__(self) -> "Relay":
        return self

    def __exit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> None:
        self.close()

    def close(self) -> None:
        """Closes every watch opened through this relay, then the connection (``QUIT``)."""
        for w in list(self._watches):
            w.close()
        with self._lock:
            self._lines.quit(1.0 if self.timeout is None else min(self.timeout, 1.0))

    @property
    def closed(self) -> bool:
        return self._lines.closed

    def _request(self, line: str) -> str:
        with self._lock:
            if self._lines.closed:
                raise RelayConnectionError(f"relay {self._lines.where}: connection closed")
            self._lines.send(line)
            while True:
                try:
                    answer = self._lines.readline(self.timeout)
                except TimeoutError:
                    self._lines.close()
                    raise
                # Nothing is watched on this connection, so pushes cannot come; if one
                # does, it is not the answer.
                if answer.startswith(("UPD ", "LOST")):
                    continue
                err = parse_error(answer, line)
                if err is not None:
                    raise err
                return answer

    def set(self, key: str, value: object) -> None:
        """Binds ``key`` (``*.var.x`` published to the team, ``local.var.x`` this robot
        only) to ``value``; see :func:`encode_value` for the types. Raises
        ``RelayError`` when the relay refuses (420: another robot's key, 410: bad key,
        422: too large), ``TypeError``/``ValueError`` for a value that cannot be sent
        exactly (nothing is sent then)."""
        literal = encode_value(value)
        if needs_wide_floats(value) and not self._wide_floats():
            raise narrow_error(value)
        self._request(f"SETV {check_word('key', key)} {literal}")

    def _wide_floats(self) -> bool:
        """Whether the relay keeps float lists as 64-bit floats (asked once, by writing
        ``FLOAT_PROBE_KEY``, only when a list needs it)."""
        if self._wide is None:
            self._request(f"SETV {FLOAT_PROBE_KEY} [{FLOAT_PROBE!r}]")
            b = self.get(FLOAT_PROBE_KEY)
            self._wide = b is not None and b.value == [FLOAT_PROBE]
        return self._wide

    def get(self, key: str, max_age_ms: Optional[int] = None) -> Optional[Binding]:
        """The binding of ``key`` (``*.var.x``: the newest copy of any robot), or
        ``None`` if no value is bound to it. With ``max_age_ms``, a value older than
        that raises ``RelayError`` with code 406 (relay protocol 2 and later)."""
        try:
            answer = self._request(getv_line(key, max_age_ms))
        except Exception as e:
            if getattr(e, "code", None) == 404:
                return None
            raise
        binding = parse_binding(answer, self.robot)
        if binding is None:
            raise RelayConnectionError(f"unexpected answer {answer!r} to GETV {key}")
        return binding

    def post(self, queue: str, value: object) -> None:
        """Posts ``value`` to this robot's talk queue ``queue`` (``plan`` or
        ``*.talk.plan``): delivered in order, exactly once, to every robot watching
        ``+.talk.plan``, or reported lost there (:class:`TalkLost`)."""
        self.set(talk_key(queue), value)

    @overload
    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: Literal["raise"] = "raise",
    ) -> "Watch[Binding]": ...

    @overload
    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        *,
        lost: Literal["event"],
    ) -> "Watch[Union[Binding, TalkLost]]": ...

    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: str = "raise",
    ) -> "Watch[Binding] | Watch[Union[Binding, TalkLost]]":
        """Bindings matching ``pattern`` (``+`` one level, ``#`` the rest; a list for
        several) as they change: with ``interval_ms=0`` each change is pushed as it
        happens; otherwise every matching binding every ``interval_ms``. Either way the
        current values come first. Talk messages of watched queues arrive as they are
        delivered. ``timeout``: seconds to wait for the next update before
        ``TimeoutError`` (``None``: forever). ``lost``: ``"raise"`` raises
        :class:`TalkLost` from the iteration (it can go on afterwards), ``"event"``
        yields it among the bindings.

        The watch has a connection of its own; it is closed by ``close()``, by leaving
        ``with``, or with this relay."""
        w: Watch[Binding] = Watch(self, check_patterns(pattern), check_interval(interval_ms), timeout, lost)
        self._watches.append(w)
        return w


class Watch(Iterator[T]):
    """An iterator of updates from one watch; see :meth:`Relay.watch`."""

    def __init__(
        self,
        relay: Relay,
        patterns: List[str],
        interval_ms: int,
        timeout: Optional[float],
        lost: str,
    ) -> None:
        if lost not in ("raise", "event"):
            raise ValueError('lost must be "raise" or "event"')
        self._relay = relay
        self._lost = lost
        self.patterns = patterns
        self.interval_ms = interval_ms
        self.timeout = timeout
        self._closing = False
        self._lines = _Lines(relay.host, relay.port, relay.timeout)
        try:
            for p in patterns:
                self._ask(f"ADDW {p}")
            self._ask(f"REFR {interval_ms}")
        except BaseException:
            self._lines.close()
            raise

    def _ask(self, line: str) -> None:
        self._lines.send(line)
        answer = self._lines.readline(self._relay.timeout)
        err = parse_error(answer, line)
        if err is not None:
            raise err

    def __iter__(self) -> "Watch[T]":
        return self

    def __next__(self) -> T:
        while True:
            if self._lines.closed and not self._lines.buf:
                raise StopIteration
            try:
                line = self._lines.readline(self.timeout)
            except RelayConnectionError:
                if self._closing:
                    raise StopIteration from None
                raise
            binding = parse_binding(line, self._lines.robot)
            if binding is not None:
                return cast(T, binding)
            lost = parse_lost(line)
            if lost is not None:
                if self._lost == "event":
                    return cast(T, lost)
                raise lost
            err = parse_error(line)
            if err is not None:
                raise err
            if line == "BYE":
                self._lines.close()
                raise StopIteration

    def close(self) -> None:
        """Ends the watch (``QUIT``) and closes its connection; iteration then stops."""
        self._closing = True
        self._lines.quit(0.5)
        self._lines.buf.clear()
        if self in self._relay._watches:
            self._relay._watches.remove(self)

    def __enter__(self) -> "Watch[T]":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
