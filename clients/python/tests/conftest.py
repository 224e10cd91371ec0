"""Real daemons on loopback for the client's tests.

Each test module gets two daemons (robots 1 and 2) on a multicast group and UDP port of
its own (239.255.x.y, a port the kernel picked) with relays on free TCP ports, all on
127.0.0.1: nothing leaves the machine. The binary is ``$HUDDLE_BIN`` (set by
``tests/python_client.rs`` under ``cargo test``), else ``target/debug/huddle``.
"""

from __future__ import annotations

import asyncio
import os
import random
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, List, Optional

import pytest

PACKAGE_DIR = Path(__file__).resolve().parent.parent
REPO = PACKAGE_DIR.parent.parent
sys.path.insert(0, str(PACKAGE_DIR))

from huddle_client import AsyncRelay, Relay  # noqa: E402


def huddle_bin() -> str:
    env = os.environ.get("HUDDLE_BIN")
    if env:
        return env
    for build in ("debug", "release"):
        path = REPO / "target" / build / "huddle"
        if path.exists():
            return str(path)
    pytest.skip("no huddle binary: run `cargo build` first, or set HUDDLE_BIN")
    raise AssertionError("unreachable")


def free_tcp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def scratch_group() -> str:
    """A multicast group and UDP port of this run's own."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"239.255.{random.randint(1, 254)}.{random.randint(1, 254)}:{port}"


@dataclass
class Daemon:
    robot: int
    port: int
    proc: subprocess.Popen  # type: ignore[type-arg]

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def start_daemon(robot: int, group: str, config_dir: Path, port: Optional[int] = None) -> Daemon:
    """A daemon for ``robot``; on ``port`` (a restart) or on a free one."""
    port = free_tcp_port() if port is None else port
    proc = subprocess.Popen(
        [
            huddle_bin(),
            "daemon",
            "--id", str(robot),
            "--group", group,
            "--iface", "127.0.0.1",
            "--relay", f"127.0.0.1:{port}",
            "--refresh", "50ms",
            "--config-dir", str(config_dir),
            "-q",
        ],
        stdout=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 15
    while True:
        if proc.poll() is not None:
            raise RuntimeError(f"daemon {robot} exited at start with {proc.returncode}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1) as s:
                if s.recv(64).startswith(b"HUDDLE "):
                    return Daemon(robot, port, proc)
        except OSError:
            pass
        if time.monotonic() > deadline:
            proc.kill()
            raise RuntimeError(f"daemon {robot}'s relay never came up")
        time.sleep(0.05)


@dataclass
class Team:
    a: Daemon
    b: Daemon
    group: str
    config_dir: Path


@pytest.fixture(scope="module")
def team(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Team]:
    config_dir = tmp_path_factory.mktemp("config")
    group = scratch_group()
    a = start_daemon(1, group, config_dir)
    try:
        b = start_daemon(2, group, config_dir)
    except BaseException:
        a.stop()
        raise
    try:
        yield Team(a, b, group, config_dir)
    finally:
        a.stop()
        b.stop()


class _AsyncWatchAdapter:
    """Drives an AsyncWatch step by step on the adapter's loop."""

    def __init__(self, owner: "AsyncAdapter", watch: Any) -> None:
        self._owner = owner
        self._watch = watch

    def __iter__(self) -> "_AsyncWatchAdapter":
        return self

    def __next__(self) -> Any:
        try:
            return self._owner._run(self._watch.__anext__())
        except StopAsyncIteration:
            raise StopIteration from None

    def close(self) -> None:
        self._owner._run(self._watch.close())

    def latest(self) -> Any:
        return self._watch.latest()

    def __enter__(self) -> "_AsyncWatchAdapter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class AsyncAdapter:
    """AsyncRelay behind the blocking Relay's interface, so that the same tests run
    against both: every call runs the coroutine to completion on a loop of its own."""

    def __init__(self, host: str = "127.0.0.1", port: int = 2001, timeout: Optional[float] = 5.0):
        self._loop = asyncio.new_event_loop()
        self._relay = AsyncRelay(host, port, timeout)
        try:
            self._run(self._relay.connect())
        except BaseException:
            self._loop.close()
            raise
        self.robot = self._relay.robot
        self.version = self._relay.version

    def _run(self, coro: Any) -> Any:
        return self._loop.run_until_complete(coro)

    def set(self, key: str, value: object) -> None:
        self._run(self._relay.set(key, value))

    def get(self, key: str, max_age_ms: Optional[int] = None) -> Any:
        return self._run(self._relay.get(key, max_age_ms))

    def post(self, queue: str, value: object) -> None:
        self._run(self._relay.post(queue, value))

    def __getattr__(self, name: str) -> Any:
        # Every other coroutine method (keys, stats, the team layer's), run to the end.
        attr = getattr(self._relay, name)
        if asyncio.iscoroutinefunction(attr):
            return lambda *args, **kwargs: self._run(attr(*args, **kwargs))
        return attr

    def watch(self, *args: Any, **kwargs: Any) -> _AsyncWatchAdapter:
        w = self._relay.watch(*args, **kwargs)
        self._run(w.open())
        return _AsyncWatchAdapter(self, w)

    @property
    def closed(self) -> bool:
        return self._relay.closed

    def close(self) -> None:
        self._run(self._relay.close())

    def shutdown(self) -> None:
        self.close()
        self._loop.close()

    def __enter__(self) -> "AsyncAdapter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


Connect = Callable[..., Any]


@pytest.fixture(params=["sync", "async"])
def connect(request: pytest.FixtureRequest) -> Iterator[Connect]:
    """Opens a client (Relay, or AsyncRelay through the adapter) to a daemon's port;
    everything opened is closed after the test."""
    opened: List[Any] = []

    def open_client(port: int, host: str = "127.0.0.1", timeout: Optional[float] = 5.0) -> Any:
        cls = Relay if request.param == "sync" else AsyncAdapter
        client = cls(host, port, timeout)
        opened.append(client)
        return client

    yield open_client
    for c in opened:
        if isinstance(c, AsyncAdapter):
            c.shutdown()
        else:
            c.close()
