"""The asyncio client: :class:`AsyncRelay` and its :class:`AsyncWatch`, the same methods
as the blocking ones, awaited."""

from __future__ import annotations

import asyncio
from types import TracebackType
from typing import AsyncIterator, List, Literal, Optional, Sequence, Type, TypeVar, Union, cast, overload

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
            raise TimeoutError(f"relay {self.where}: no connection within {timeout} s") from None
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
            raise TimeoutError(f"relay {self.where}: no answer within {timeout} s") from None
        except (OSError, ValueError, asyncio.LimitOverrunError) as e:
            await self.close()
            raise RelayConnectionError(f"relay {self.where}: {e}") from e
        if not raw.endswith(b"\n"):
            await self.close()
            raise RelayConnectionError(f"relay {self.where} closed the connection")
        return raw.decode("utf-8", "replace").rstrip("\r\n")

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


class AsyncRelay:
    """The asyncio twin of :class:`~huddle_client.Relay`::

        async with AsyncRelay("127.0.0.1", 2001) as relay:
            await relay.set("*.var.ball.dist", 1.5)
            async for b in relay.watch("+.var.ball.#"):
                ...

    Connect with ``async with`` or ``await relay.connect()``. Requests from several
    tasks are answered in turn.
    """

    def __init__(
        self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, timeout: Optional[float] = 5.0
    ) -> None:
        self.host = host
        self.port = port
        self.timeout = timeout
        self._lines = _AsyncLines(host, port)
        self._wide: Optional[bool] = None
        self._lock: Optional[asyncio.Lock] = None  # made on the loop that connects
        self._watches: List[AsyncWatch] = []  # type: ignore[type-arg]
        self.version = 0
        self.robot = 0

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
        for w in list(self._watches):
            await w.close()
        if self._lock is None:
            return
        async with self._lock:
            await self._lines.quit(1.0 if self.timeout is None else min(self.timeout, 1.0))

    @property
    def closed(self) -> bool:
        return self._lines.closed

    async def _request(self, line: str) -> str:
        if self._lock is None:
            raise RelayConnectionError("not connected: use `async with` or `await relay.connect()`")
        async with self._lock:
            await self._lines.send(line)
            while True:
                try:
                    answer = await self._lines.readline(self.timeout)
                except TimeoutError:
                    await self._lines.close()
                    raise
                if answer.startswith(("UPD ", "LOST")):
                    continue
                err = parse_error(answer, line)
                if err is not None:
                    raise err
                return answer

    async def set(self, key: str, value: object) -> None:
        """As :meth:`Relay.set <huddle_client.Relay.set>`."""
        literal = encode_value(value)
        if needs_wide_floats(value) and not await self._wide_floats():
            raise narrow_error(value)
        await self._request(f"SETV {check_word('key', key)} {literal}")

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
        except Exception as e:
            if getattr(e, "code", None) == 404:
                return None
            raise
        binding = parse_binding(answer, self.robot)
        if binding is None:
            raise RelayConnectionError(f"unexpected answer {answer!r} to GETV {key}")
        return binding

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
    ) -> "AsyncWatch[Binding]": ...

    @overload
    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        *,
        lost: Literal["event"],
    ) -> "AsyncWatch[Union[Binding, TalkLost]]": ...

    def watch(
        self,
        pattern: Union[str, Sequence[str]],
        interval_ms: int = 0,
        timeout: Optional[float] = None,
        lost: str = "raise",
    ) -> "AsyncWatch[Binding] | AsyncWatch[Union[Binding, TalkLost]]":
        """As :meth:`Relay.watch <huddle_client.Relay.watch>`, an async iterator. It
        connects on first use (``async for``, ``async with`` or ``await w.open()``)."""
        w: AsyncWatch[Binding] = AsyncWatch(
            self, check_patterns(pattern), check_interval(interval_ms), timeout, lost
        )
        self._watches.append(w)
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
    ) -> None:
        if lost not in ("raise", "event"):
            raise ValueError('lost must be "raise" or "event"')
        self._relay = relay
        self._lost = lost
        self.patterns = patterns
        self.interval_ms = interval_ms
        self.timeout = timeout
        self._lines = _AsyncLines(relay.host, relay.port)
        self._opened = False
        self._closing = False

    async def open(self) -> "AsyncWatch[T]":
        """Connects and subscribes (done by the first ``async for`` step otherwise)."""
        if self._opened:
            return self
        self._opened = True
        try:
            await self._lines.open(self._relay.timeout)
            for p in self.patterns:
                await self._ask(f"ADDW {p}")
            await self._ask(f"REFR {self.interval_ms}")
        except BaseException:
            await self._lines.close()
            raise
        return self

    async def _ask(self, line: str) -> None:
        await self._lines.send(line)
        answer = await self._lines.readline(self._relay.timeout)
        err = parse_error(answer, line)
        if err is not None:
            raise err

    def __aiter__(self) -> "AsyncWatch[T]":
        return self

    async def __anext__(self) -> T:
        if self._closing:
            raise StopAsyncIteration
        await self.open()
        while True:
            try:
                line = await self._lines.readline(self.timeout)
            except RelayConnectionError:
                if self._closing:
                    raise StopAsyncIteration from None
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
                await self._lines.close()
                raise StopAsyncIteration

    async def close(self) -> None:
        """Ends the watch (``QUIT``) and closes its connection; iteration then stops."""
        self._closing = True
        await self._lines.quit(0.5)
        if self in self._relay._watches:
            self._relay._watches.remove(self)

    async def __aenter__(self) -> "AsyncWatch[T]":
        return await self.open()

    async def __aexit__(self, *exc: object) -> None:
        await self.close()
