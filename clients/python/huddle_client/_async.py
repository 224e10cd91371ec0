"""The asyncio client: :class:`AsyncRelay` and its :class:`AsyncWatch`, the same methods
as the blocking ones, awaited."""

from __future__ import annotations

import asyncio
from types import TracebackType
import time
from typing import (
    Any,
    AsyncIterator,
    Awaitable,
    Callable,
    Dict,
    List,
    Literal,
    Optional,
    Sequence,
    Type,
    TypeVar,
    Union,
    cast,
    overload,
)

from ._team import AsyncTeamMixin
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

T = TypeVar("T")

#: The longest line read from the relay.
MAX_LINE = 16 << 20


class _AsyncLines:
    """A relay connection over asyncio streams, read line by line."""

    def __init__(self, host: str, port: int) -> None:
        self.where = f"{host}:{port}"
        self.host = host
        self.port = port
        self.reader: Optional[asyncio.StreamReader] = None
        self.writer: Optional[asyncio.StreamWriter] = None
        self.closed = False
        self.version = 0
        self.robot = 0

    async def open(self, timeout: Optional[float]) -> None:
        try:
            self.reader, self.writer = await asyncio.wait_for(
                asyncio.open_connection(self.host, self.port, limit=MAX_LINE), timeout
            )
        except asyncio.TimeoutError:
            raise RelayTimeout(f"relay {self.where}: no connection within {timeout} s") from None
        except OSError as e:
            raise RelayConnectionError(
                f"cannot reach a huddle relay at {self.where}: {e} (is the daemon running?)"
            ) from e
        self.version, self.robot = parse_greeting(await self.readline(timeout))

    async def send(self, line: str) -> None:
        if self.writer is None or self.closed:
            raise RelayConnectionError(f"relay {self.where}: connection closed")
        try:
            self.writer.write(line.encode("utf-8") + b"\n")
            await self.writer.drain()
        except OSError as e:
            await self.close()
            raise RelayConnectionError(f"relay {self.where}: {e}") from e

    async def readline(self, timeout: Optional[float]) -> str:
        if self.reader is None or self.closed:
            raise RelayConnectionError(f"relay {self.where}: connection closed")
        try:
            raw = await asyncio.wait_for(self.reader.readline(), timeout)
        except asyncio.TimeoutError:
            raise RelayTimeout(f"relay {self.where}: no answer within {timeout} s") from None
        except (OSError, ValueError, asyncio.LimitOverrunError) as e:
            await self.close()
            raise RelayConnectionError(f"relay {self.where}: {e}") from e
        if not raw.endswith(b"\n"):
            await self.close()
            raise RelayConnectionError(f"relay {self.where} closed the connection")
        return raw.decode("utf-8", "replace").rstrip("\r\n")

    def dead(self) -> bool:
        """Whether the relay has closed this connection (seen without waiting)."""
        if self.closed or self.reader is None:
            return True
        if self.reader.at_eof() or (self.writer is not None and self.writer.is_closing()):
            return True
        return False

    async def quit(self, timeout: float) -> None:
        if self.closed or self.writer is None:
            self.closed = True
            return
        try:
            await self.send("QUIT")
            loop = asyncio.get_running_loop()
            end = loop.time() + timeout
            while loop.time() < end:
                if await self.readline(max(end - loop.time(), 0.001)) == "BYE":
                    break
        except (OSError, TimeoutError, RelayConnectionError):
            pass
        await self.close()

    async def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self.writer is not None:
            self.writer.close()
            try:
                await self.writer.wait_closed()
            except (OSError, asyncio.CancelledError):
                pass


async def _connect_with_backoff(
    host: str,
    port: int,
    timeout: Optional[float],
    deadline: Optional[float],
    stop: Callable[[], bool] = lambda: False,
) -> _AsyncLines:
    """As the blocking client's: a new connection, retried with backoff."""
    delays = backoff_delays()
    while True:
        lines = _AsyncLines(host, port)
        try:
            await lines.open(timeout)
            return lines
        except (RelayConnectionError, RelayTimeout):
            await lines.close()
            wait = next(delays)
            if stop() or (deadline is not None and time.monotonic() + wait > deadline):
                raise
            await asyncio.sleep(wait)


class AsyncRelay(AsyncTeamMixin):
    """The asyncio twin of :class:`~huddle_client.Relay`::

        async with AsyncRelay("127.0.0.1", 2001) as relay:
            await relay.set("*.var.ball.dist", 1.5)
            async for b in relay.watch("+.var.ball.#"):
                ...

    Connect with ``async with`` or ``await relay.connect()``. Requests from several
    tasks are answered in turn. Reconnecting, timeouts and errors are as for
    :class:`~huddle_client.Relay`.
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
        self._lines = _AsyncLines(host, port)
        self._wide: Optional[bool] = None
        self._lock: Optional[asyncio.Lock] = None  # made on the loop that connects
        self._watches: List[AsyncWatch] = []  # type: ignore[type-arg]
        self._closed = False
        self.version = 0
        self.robot = 0
        self.reconnects = 0

    async def connect(self) -> "AsyncRelay":
        """Connects and reads the greeting (``robot``, ``version``)."""
        self._lock = asyncio.Lock()
        await self._lines.open(self.timeout)
        self.version, self.robot = self._lines.version, self._lines.robot
        return self

    async def __aenter__(self) -> "AsyncRelay":
        return await self.connect()

    async def __aexit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> None:
        await self.close()

    async def close(self) -> None:
        """Closes every watch opened through this relay, then the connection."""
        self._closed = True
        for w in list(self._watches):
            await w.close()
        if self._lock is None:
            return
        async with self._lock:
            await self._lines.quit(1.0 if self.timeout is None else min(self.timeout, 1.0))

    @property
    def closed(self) -> bool:
        return self._closed or (self._lines.closed and not self.reconnect)

    async def _live_lines(self) -> _AsyncLines:
        if self._closed:
            raise RelayConnectionError(f"relay {self._lines.where}: closed by close()")
        if not self._lines.dead():
            return self._lines
        if not self.reconnect:
            raise RelayConnectionError(f"relay {self._lines.where}: connection closed")
        await self._lines.close()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        self._lines = await _connect_with_backoff(self.host, self.port, self.timeout, deadline)
        self.version, self.robot = self._lines.version, self._lines.robot
        self._wide = None
        self.reconnects += 1
        return self._lines

    async def _request(self, line: str, resend: bool = True) -> str:
        if self._lock is None:
            raise RelayConnectionError("not connected: use `async with` or `await relay.connect()`")
        async with self._lock:
            for attempt in (0, 1):
                lines = await self._live_lines()
                try:
                    await lines.send(line)
                    return await self._answer(lines, line)
                except RelayConnectionError:
                    if attempt == 1 or not (self.reconnect and resend) or self._closed:
                        raise
            raise AssertionError("unreachable")  # pragma: no cover

    async def _answer(self, lines: _AsyncLines, line: str) -> str:
        while True:
            try:
                answer = await lines.readline(self.timeout)
            except RelayTimeout:
                await lines.close()
                raise
            if answer.startswith(("UPD ", "LOST")):
                continue
            err = parse_error(answer, line)
            if err is not None:
                raise err
            return answer

    async def set(self, key: str, value: object) -> None:
        """As :meth:`Relay.set <huddle_client.Relay.set>`."""
        value = plain_value(value)
        literal = encode_value(value)
        if needs_wide_floats(value) and not await self._wide_floats():
            raise narrow_error(value)
        word = check_word("key", key)
        await self._request(f"SETV {word} {literal}", resend=".talk." not in word)

    async def _wide_floats(self) -> bool:
        if self._wide is None:
            await self._request(f"SETV {FLOAT_PROBE_KEY} [{FLOAT_PROBE!r}]")
            b = await self.get(FLOAT_PROBE_KEY)
            self._wide = b is not None and b.value == [FLOAT_PROBE]
        return self._wide

    async def get(self, key: str, max_age_ms: Optional[int] = None) -> Optional[Binding]:
        """As :meth:`Relay.get <huddle_client.Relay.get>`."""
        try:
            answer = await self._request(getv_line(key, max_age_ms))
        except RelayError as e:
            if e.code == 404:
                return None
            raise
        binding = parse_binding(answer, self.robot)
        if binding is None:
            raise RelayConnectionError(f"unexpected answer {answer!r} to GETV {key}")
        return binding

    async def snapshot(self, pattern: Union[str, Sequence[str]] = "#") -> Dict[str, Binding]:
        """As :meth:`Relay.snapshot <huddle_client.Relay.snapshot>`."""
        patterns = check_patterns(pattern)
        if self._lock is None:
            raise RelayConnectionError("not connected: use `async with` or `await relay.connect()`")
        async with self._lock:
            for attempt in (0, 1):
                lines = await self._live_lines()
                reader = SnapshotReader(self.robot)
                try:
                    for text in snapshot_lines(patterns):
                        await lines.send(text)
                    while not reader.done:
                        try:
                            reader.feed(await lines.readline(self.timeout))
                        except RelayTimeout:
                            await lines.close()
                            raise
                    break
                except RelayConnectionError:
                    if attempt == 1 or not self.reconnect:
                        raise
        if reader.error is not None:
            raise reader.error
        return dict(sorted(reader.bindings.items()))

    async def keys(self, pattern: Union[str, Sequence[str]] = "#", internal: bool = False) -> List[str]:
        """As :meth:`Relay.keys <huddle_client.Relay.keys>`."""
        return [k for k in await self.snapshot(pattern) if internal or not is_internal(k)]

    async def stats(self) -> Dict[str, Union[int, float, bool, str]]:
        """As :meth:`Relay.stats <huddle_client.Relay.stats>`."""
        out: Dict[str, Union[int, float, bool, str]] = {}
        for k, b in (await self.snapshot(STATS_PREFIX + "#")).items():
            if isinstance(b.value, (int, float, bool, str)):
                out[k[len(STATS_PREFIX) :]] = b.value
        return out

    async def post(self, queue: str, value: object) -> None:
        """As :meth:`Relay.post <huddle_client.Relay.post>`."""
        await self.set(talk_key(queue), value)

    @overload
    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: Literal["raise"] = "raise",
        events: Literal[False] = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "AsyncWatch[Binding]": ...

    @overload
    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: str = "raise",
        events: bool = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "AsyncWatch[Union[Binding, TalkLost, Event]]": ...

    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: str = "raise",
        events: bool = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "AsyncWatch[Any]":
        """As :meth:`Relay.watch <huddle_client.Relay.watch>`, an async iterator. It
        connects on first use (``async for``, ``async with`` or ``await w.open()``)."""
        w: AsyncWatch[Any] = AsyncWatch(
            self, check_patterns(pattern), check_interval(interval_ms), timeout, lost, events, probe_ms
        )
        self._watches.append(w)
        return w

    def subscribe(
        self,
        pattern: Union[str, Sequence[str]],
        callback: Callable[[Any], Union[None, Awaitable[None]]],
        interval_ms: int = 0,
        events: bool = False,
        probe_ms: Optional[int] = DEFAULT_PROBE_MS,
    ) -> "AsyncWatch[Any]":
        """As :meth:`Relay.subscribe <huddle_client.Relay.subscribe>`, on a task of
        this loop; ``callback`` may be a plain function or a coroutine function."""
        w = self.watch(pattern, interval_ms, None, "event", events, probe_ms)
        w._start_task(callback)
        return w


class AsyncWatch(AsyncIterator[T]):
    """An async iterator of updates from one watch; see :meth:`AsyncRelay.watch`."""

    def __init__(
        self,
        relay: AsyncRelay,
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
        self._lines = _AsyncLines(relay.host, relay.port)
        self._opened = False
        self._closing = False
        self._book = WatchBook(probe_ms if interval_ms == 0 else None)
        self._queue: List[Any] = []
        self._task: Optional["asyncio.Task[None]"] = None
        #: The exception that stopped a subscription's callback, if any.
        self.error: Optional[BaseException] = None

    async def open(self) -> "AsyncWatch[T]":
        """Connects and subscribes (done by the first ``async for`` step otherwise)."""
        if self._opened:
            return self
        self._opened = True
        try:
            await self._lines.open(self._relay.timeout)
            await self._subscribe()
        except BaseException:
            await self._lines.close()
            raise
        return self

    async def _subscribe(self) -> None:
        for p in self.patterns:
            await self._ask(f"ADDW {p}")
        await self._ask(f"REFR {self.interval_ms}")

    async def _ask(self, line: str) -> None:
        await self._lines.send(line)
        while True:
            answer = await self._lines.readline(self._relay.timeout)
            if answer.startswith(("UPD ", "LOST")):
                self._take_line(answer)
                continue
            err = parse_error(answer, line)
            if err is not None:
                raise err
            return

    def latest(self) -> Dict[str, Binding]:
        """As :meth:`Watch.latest <huddle_client.Watch.latest>`."""
        return self._book.snapshot()

    def __aiter__(self) -> "AsyncWatch[T]":
        return self

    def _take_line(self, line: str) -> None:
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
            self._lines.closed = True

    async def _reconnect(self, deadline: Optional[float]) -> None:
        await self._lines.close()
        relay = self._relay
        self._lines = await _connect_with_backoff(
            relay.host, relay.port, relay.timeout, deadline, lambda: self._closing
        )
        self._book.probing.clear()
        await self._subscribe()
        self._queue.insert(0, Reconnected(self._lines.robot))

    async def __anext__(self) -> T:
        await self.open()
        deadline = None if self.timeout is None else time.monotonic() + self.timeout
        while True:
            while self._queue:
                item = self._queue.pop(0)
                if not isinstance(item, (Binding, TalkLost)):
                    if self._events:
                        return cast(T, item)
                    continue
                if isinstance(item, TalkLost) and self._lost == "raise":
                    raise item
                return cast(T, item)
            if self._closing:
                raise StopAsyncIteration
            if self._lines.closed:
                if not self._relay.reconnect or self._relay._closed:
                    raise StopAsyncIteration
                await self._reconnect(deadline)
                continue
            probe_at = self._book.next_due()
            if probe_at is not None and probe_at <= time.monotonic():
                for key in self._book.due(time.monotonic()):
                    await self._lines.send(f"GETV {key}")
                continue
            wait = None if deadline is None else max(deadline - time.monotonic(), 0.0)
            if probe_at is not None:
                until_probe = max(probe_at - time.monotonic(), 0.0)
                wait = until_probe if wait is None else min(wait, until_probe)
            try:
                line = await self._lines.readline(wait)
            except RelayTimeout:
                if deadline is not None and time.monotonic() >= deadline:
                    raise RelayTimeout(
                        f"watch {' '.join(self.patterns)}: no update within {self.timeout} s"
                    ) from None
                continue
            except RelayConnectionError:
                if self._closing:
                    raise StopAsyncIteration from None
                if not self._relay.reconnect:
                    raise
                await self._reconnect(deadline)
                continue
            self._take_line(line)

    def _start_task(self, callback: Callable[[Any], Union[None, Awaitable[None]]]) -> None:
        async def run() -> None:
            try:
                async for item in self:
                    result = callback(item)
                    if asyncio.iscoroutine(result):
                        await result
            except asyncio.CancelledError:
                pass
            except Exception as e:  # kept for the program to see
                if not self._closing:
                    self.error = e

        self._task = asyncio.get_running_loop().create_task(run())

    async def close(self) -> None:
        """Ends the watch (``QUIT``) and closes its connection; iteration then stops."""
        self._closing = True
        if self._task is not None and self._task is not asyncio.current_task():
            self._task.cancel()
            try:
                await self._task
            except (asyncio.CancelledError, Exception):
                pass
        await self._lines.quit(0.5)
        if self in self._relay._watches:
            self._relay._watches.remove(self)

    async def __aenter__(self) -> "AsyncWatch[T]":
        return await self.open()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
