"""The blocking client: :class:`Relay` and its :class:`Watch`."""

from __future__ import annotations

import socket
import threading
import time
from types import TracebackType
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence, Type, TypeVar, Union, cast, overload

from ._protocol import (
    DEFAULT_PORT,
    DEFAULT_PROBE_MS,
    STATS_PREFIX,
    Binding,
    Event,
    Reconnected,
    RelayConnectionError,
    RelayError,
    RelayTimeout,
    SnapshotReader,
    TalkLost,
    WatchBook,
    backoff_delays,
    is_internal,
    plain_value,
    snapshot_lines,
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

from ._team import TeamMixin

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
                raise RelayTimeout(f"relay {self.where}: no answer within {timeout} s")
            self.sock.settimeout(left)
            try:
                chunk = self.sock.recv(65536)
            except socket.timeout:
                raise RelayTimeout(f"relay {self.where}: no answer within {timeout} s") from None
            except OSError as e:
                self.close()
                raise RelayConnectionError(f"relay {self.where}: {e}") from e
            if not chunk:
                self.close()
                raise RelayConnectionError(f"relay {self.where} closed the connection")
            self.buf += chunk

    def dead(self) -> bool:
        """Whether the relay has closed this connection (a daemon restart), seen without
        waiting: a closed connection reads end-of-file at once."""
        if self.closed:
            return True
        if self.buf:
            return False
        try:
            self.sock.setblocking(False)
            try:
                peeked = self.sock.recv(1, socket.MSG_PEEK)
            finally:
                self.sock.setblocking(True)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:
            self.close()
            return True
        if not peeked:
            self.close()
            return True
        return False

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


def _connect_with_backoff(
    host: str,
    port: int,
    timeout: Optional[float],
    deadline: Optional[float],
    stop: Callable[[], bool] = lambda: False,
) -> _Lines:
    """A new connection, retried with backoff until ``deadline`` (``time.monotonic()``;
    ``None``: forever) or ``stop()``; the last failure is raised after it."""
    delays = backoff_delays()
    while True:
        try:
            return _Lines(host, port, timeout)
        except (RelayConnectionError, RelayTimeout):
            wait = next(delays)
            if stop() or (deadline is not None and time.monotonic() + wait > deadline):
                raise
            time.sleep(wait)


class Relay(TeamMixin):
    """A connection to a huddle daemon's relay (``huddle daemon``, TCP port 2001).

    Use it as a context manager; every method is blocking and thread-safe::

        with Relay("127.0.0.1", 2001) as relay:
            relay.set("*.var.ball.dist", 1.5)

    ``timeout`` (seconds) bounds connecting and each answer; a timed-out connection is
    closed (its answer could arrive later and be taken for the next one's) and
    :class:`RelayTimeout` raised. With ``reconnect`` (the default), a request finding
    the connection gone (a daemon restart, a timeout before) connects again, retrying
    with backoff (50 ms doubling to 1 s) for up to ``timeout`` seconds, and is sent
    there; watches resubscribe by themselves. A talk post whose connection drops after
    it was sent is not sent twice: it raises :class:`RelayConnectionError`.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        timeout: Optional[float] = 5.0,
        reconnect: bool = True,
    ) -> None:
        self.host = host
        self.port = port
        self.timeout = timeout
        self.reconnect = reconnect
        self._lines = _Lines(host, port, timeout)
        self._lock = threading.Lock()
        self._wide: Optional[bool] = None
        self._watches: List[Watch] = []  # type: ignore[type-arg]
        self._closed = False
        #: The relay protocol version from the greeting.
        self.version: int = self._lines.version
        #: The id of the robot this relay belongs to.
        self.robot: int = self._lines.robot
        #: How many times this relay connected again after losing its connection.
        self.reconnects = 0

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
        self._closed = True
        for w in list(self._watches):
            w.close()
        with self._lock:
            self._lines.quit(1.0 if self.timeout is None else min(self.timeout, 1.0))

    @property
    def closed(self) -> bool:
        return self._closed or (self._lines.closed and not self.reconnect)

    def _live_lines(self) -> _Lines:
        """The connection, connected again first if it is gone (lock held)."""
        if self._closed:
            raise RelayConnectionError(f"relay {self._lines.where}: closed by close()")
        if not self._lines.dead():
            return self._lines
        if not self.reconnect:
            raise RelayConnectionError(f"relay {self._lines.where}: connection closed")
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        self._lines = _connect_with_backoff(self.host, self.port, self.timeout, deadline)
        self.version, self.robot = self._lines.version, self._lines.robot
        self._wide = None  # perhaps another build of the daemon
        self.reconnects += 1
        return self._lines

    def _request(self, line: str, resend: bool = True) -> str:
        with self._lock:
            for attempt in (0, 1):
                lines = self._live_lines()
                try:
                    lines.send(line)
                    return self._answer(lines, line)
                except RelayConnectionError:
                    # Dropped while asking: ask the new connection, once, when asking
                    # twice does no harm.
                    if attempt == 1 or not (self.reconnect and resend) or self._closed:
                        raise
            raise AssertionError("unreachable")  # pragma: no cover

    def _answer(self, lines: _Lines, line: str) -> str:
        while True:
            try:
                answer = lines.readline(self.timeout)
            except RelayTimeout:
                lines.close()
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
        only) to ``value``; see :func:`encode_value` for the types (numpy scalars and
        1-D arrays included). Raises ``RelayError`` when the relay refuses (420:
        another robot's key, 410: bad key, 422: too large, 423: the daemon's own key,
        such as the team layer's ``local.var.team.*``), ``TypeError``/``ValueError``
        for a value that cannot be sent exactly (nothing is sent then)."""
        value = plain_value(value)
        literal = encode_value(value)
        if needs_wide_floats(value) and not self._wide_floats():
            raise narrow_error(value)
        word = check_word("key", key)
        self._request(f"SETV {word} {literal}", resend=".talk." not in word)

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
        except RelayError as e:
            if e.code == 404:
                return None
            raise
        binding = parse_binding(answer, self.robot)
        if binding is None:
            raise RelayConnectionError(f"unexpected answer {answer!r} to GETV {key}")
        return binding

    def snapshot(self, pattern: Union[str, Sequence[str]] = "#") -> Dict[str, Binding]:
        """Every binding matching ``pattern`` now, by key (in key order). Talk queues
        have no value and are not listed."""
        patterns = check_patterns(pattern)
        with self._lock:
            for attempt in (0, 1):
                lines = self._live_lines()
                reader = SnapshotReader(self.robot)
                try:
                    for text in snapshot_lines(patterns):
                        lines.send(text)
                    while not reader.done:
                        try:
                            reader.feed(lines.readline(self.timeout))
                        except RelayTimeout:
                            lines.close()
                            raise
                    break
                except RelayConnectionError:
                    if attempt == 1 or not self.reconnect:
                        raise
        if reader.error is not None:
            raise reader.error
        return dict(sorted(reader.bindings.items()))

    def keys(self, pattern: Union[str, Sequence[str]] = "#", internal: bool = False) -> List[str]:
        """The keys bound now that match ``pattern``, sorted. The daemon's own keys
        (``local.var.huddle.*``: its counters) are left out unless ``internal``."""
        return [k for k in self.snapshot(pattern) if internal or not is_internal(k)]

    def stats(self) -> Dict[str, Union[int, float, bool, str]]:
        """The daemon's counters (``frames_in``, ``drops.total``, ``peers.2.loss``, ...),
        by name: its ``local.var.huddle.stats.*`` keys."""
        out: Dict[str, Union[int, float, bool, str]] = {}
        for k, b in self.snapshot(STATS_PREFIX + "#").items():
            if isinstance(b.value, (int, float, bool, str)):
                out[k[len(STATS_PREFIX) :]] = b.value
        return out

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
        events: Literal[False] = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "Watch[Binding]": ...

    @overload
    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: str = "raise",
        events: bool = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "Watch[Union[Binding, TalkLost, Event]]": ...

    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: str = "raise",
        events: bool = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "Watch[Any]":
        """Bindings matching ``pattern`` (``+`` one level, ``#`` the rest; a list for
        several) as they change: with ``interval_ms=0`` each change is pushed as it
        happens; otherwise every matching binding every ``interval_ms``. Either way the
        current values come first. Talk messages of watched queues arrive as they are
        delivered. ``timeout``: seconds to wait for the next update before
        :class:`RelayTimeout` (``None``: forever). ``lost``: ``"raise"`` raises
        :class:`TalkLost` from the iteration (it can go on afterwards), ``"event"``
        yields it among the bindings.

        A robot that dies is not silent: its values come again flagged ``departed``,
        with their true ages (a push watch asks the relay about a robot whose values
        have not changed for ``probe_ms``; ``None`` turns that off). With ``events``,
        :class:`Joined`, :class:`Left` and :class:`Reconnected` are yielded too.
        ``watch.latest()`` is the newest value of each key with its age now.

        The watch has a connection of its own; it is closed by ``close()``, by leaving
        ``with``, or with this relay. When the daemon restarts, the watch connects
        again (with backoff) and subscribes again, if this relay has ``reconnect``."""
        w: Watch[Any] = Watch(
            self,
            check_patterns(pattern),
            check_interval(interval_ms),
            timeout,
            lost,
            events,
            probe_ms,
        )
        self._watches.append(w)
        return w

    def subscribe(
        self,
        pattern: Union[str, Sequence[str]],
        callback: Callable[[Any], None],
        interval_ms: int = 0,
        events: bool = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "Watch[Any]":
        """``callback(item)`` for each item of ``watch(pattern, ...)``, called on a
        thread of its own (so keep it short, or hand over to a queue); talk losses come
        as :class:`TalkLost` items. Returns the watch: ``close()`` it to stop. An
        exception from the callback stops the subscription; it is kept in
        ``watch.error``."""
        w = self.watch(pattern, interval_ms, None, "event", events, probe_ms)
        w._start_thread(callback)
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
        events: bool = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> None:
        if lost not in ("raise", "event"):
            raise ValueError('lost must be "raise" or "event"')
        self._relay = relay
        self._lost = lost
        self._events = events
        self.patterns = patterns
        self.interval_ms = interval_ms
        self.timeout = timeout
        self._closing = False
        self._book = WatchBook(probe_ms if interval_ms == 0 else None)
        self._queue: List[Any] = []
        self._thread: Optional[threading.Thread] = None
        #: The exception that stopped a :meth:`Relay.subscribe` callback, if any.
        self.error: Optional[BaseException] = None
        self._lines = _Lines(relay.host, relay.port, relay.timeout)
        try:
            self._subscribe()
        except BaseException:
            self._lines.close()
            raise

    def _subscribe(self) -> None:
        for p in self.patterns:
            self._ask(f"ADDW {p}")
        self._ask(f"REFR {self.interval_ms}")

    def _ask(self, line: str) -> None:
        self._lines.send(line)
        while True:
            answer = self._lines.readline(self._relay.timeout)
            if answer.startswith(("UPD ", "LOST")):
                self._take_line(answer)  # ADDW in push mode pushes at once
                continue
            err = parse_error(answer, line)
            if err is not None:
                raise err
            return

    def latest(self) -> Dict[str, Binding]:
        """The newest value of each key this watch delivered (talk aside), with its
        age now (not when it arrived), flagged ``departed`` once its robot left."""
        return self._book.snapshot()

    def __iter__(self) -> "Watch[T]":
        return self

    def _take_line(self, line: str) -> None:
        """Queues what one line from the relay delivers."""
        now = time.monotonic()
        binding = parse_binding(line, self._lines.robot)
        if binding is not None:
            if line.startswith("VAL "):
                self._queue += self._book.answered(binding, now)
            else:
                self._queue += self._book.take(binding)
            return
        lost = parse_lost(line)
        if lost is not None:
            self._queue.append(lost)
            return
        err = parse_error(line)
        if err is not None:
            if self._book.probing and err.code == 404:
                self._queue += self._book.answered(None, now)
                return
            if self._book.probing:
                self._book.probing.pop(0)
            raise err
        if line == "BYE":
            self._closing = True  # only this watch asks to quit
            self._lines.close()

    def _probe(self) -> None:
        for key in self._book.due(time.monotonic()):
            self._lines.send(f"GETV {key}")

    def _reconnect(self, deadline: Optional[float]) -> None:
        self._lines.close()
        relay = self._relay
        self._lines = _connect_with_backoff(
            relay.host, relay.port, relay.timeout, deadline, lambda: self._closing
        )
        self._book.probing.clear()
        self._subscribe()
        self._queue.insert(0, Reconnected(self._lines.robot))

    def __next__(self) -> T:
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        while True:
            while self._queue:
                item = self._queue.pop(0)
                if isinstance(item, Reconnected) or not isinstance(item, (Binding, TalkLost)):
                    if self._events:
                        return cast(T, item)
                    continue
                if isinstance(item, TalkLost) and self._lost == "raise":
                    raise item
                return cast(T, item)
            if self._closing:
                raise StopIteration
            if self._lines.closed and not self._lines.buf:
                if not self._relay.reconnect or self._relay._closed:
                    raise StopIteration
                self._reconnect(deadline)
                continue
            wait = None if deadline is None else deadline - time.monotonic()
            probe_at = self._book.next_due()
            if probe_at is not None:
                until_probe = max(probe_at - time.monotonic(), 0.0)
                wait = until_probe if wait is None else min(wait, until_probe)
            try:
                if probe_at is not None and probe_at <= time.monotonic():
                    self._probe()
                    continue
                line = self._lines.readline(max(wait, 0.0) if wait is not None else None)
            except RelayTimeout:
                if deadline is not None and time.monotonic() >= deadline:
                    raise RelayTimeout(
                        f"watch {' '.join(self.patterns)}: no update within {self.timeout} s"
                    ) from None
                continue
            except RelayConnectionError:
                if self._closing:
                    raise StopIteration from None
                if not self._relay.reconnect:
                    raise
                self._reconnect(deadline)
                continue
            self._take_line(line)

    def _start_thread(self, callback: Callable[[Any], None]) -> None:
        def run() -> None:
            try:
                for item in self:
                    callback(item)
            except BaseException as e:  # kept for the program to see
                if not self._closing:
                    self.error = e

        self._thread = threading.Thread(target=run, name=f"huddle watch {self.patterns}", daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Ends the watch (``QUIT``) and closes its connection; iteration then stops."""
        self._closing = True
        if self._thread is not None and self._thread is not threading.current_thread():
            # The thread is reading: end-of-file wakes it, then it stops.
            try:
                self._lines.sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            self._thread.join(2.0)
            self._lines.close()
        else:
            self._lines.quit(0.5)
        self._lines.buf.clear()
        if self in self._relay._watches:
            self._relay._watches.remove(self)

    def __enter__(self) -> "Watch[T]":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
