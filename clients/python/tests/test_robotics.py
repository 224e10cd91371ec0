"""What a robotics program reaches for first (issue 31): numpy values, a client that
survives a daemon restart, every failure a HuddleError, push watches that notice a dead
robot, join/leave events, keys() and stats(), callbacks, the team layer's typed keys.
Each test runs with the blocking Relay and with AsyncRelay unless it says otherwise."""

from __future__ import annotations

import asyncio
import math
import socket
import threading
import time
from pathlib import Path
from typing import Any, List

import pytest

from conftest import AsyncAdapter, scratch_group, start_daemon
from huddle_client import (
    AsyncRelay,
    Binding,
    HuddleError,
    Joined,
    Left,
    Reconnected,
    Relay,
    RelayConnectionError,
    RelayTimeout,
    TeamBall,
    encode_value,
)
from huddle_client._team import ball_value, mates_of, pose_value, team_ball_of

try:
    import numpy as np  # type: ignore[no-redef]
except ImportError:  # pragma: no cover - CI installs it
    np = None

needs_numpy = pytest.mark.skipif(np is None, reason="numpy is not installed (pip install numpy)")


# ---- numpy, in and out ------------------------------------------------------------


@needs_numpy
def test_numpy_scalars_and_arrays_go_as_their_values(team, connect):
    r = connect(team.a.port)
    cases = [
        (np.float64(1.5), "float", 1.5),
        (np.float32(0.25), "float", 0.25),
        (np.int64(-7), "int", -7),
        (np.uint8(200), "int", 200),
        (np.bool_(True), "bool", True),
        (np.array(2.5), "float", 2.5),
        (np.array([0.33, -2.25]), "floats", [0.33, -2.25]),
        (np.arange(3), "floats", [0.0, 1.0, 2.0]),
        ([np.float64(0.1), np.float32(0.5)], "floats", [0.1, 0.5]),
    ]
    for value, type_name, expected in cases:
        r.set("local.var.np", value)
        b = r.get("local.var.np")
        assert (b.type, b.value) == (type_name, expected), f"{value!r} came back as {b}"
        assert type(b.value) is type(expected), f"{value!r}: {type(b.value)}"


@needs_numpy
def test_numpy_reads_a_binding_as_an_array_and_2d_arrays_are_refused(team, connect):
    r = connect(team.a.port)
    r.set("local.var.np2", np.array([1.0, 2.0, 3.0]))
    arr = np.asarray(r.get("local.var.np2"))
    assert arr.dtype == np.float64 and arr.tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(ValueError, match="2-D"):
        r.set("local.var.np2", np.zeros((2, 2)))
    assert r.get("local.var.np2").value == [1.0, 2.0, 3.0], "nothing sent"


class _Scalar:
    """An array library's 0-d value, as numpy's duck type: .ndim, .item()."""

    ndim = 0

    def __init__(self, v: Any) -> None:
        self.v = v

    def item(self) -> Any:
        return self.v


class _Vector:
    ndim = 1

    def __init__(self, v: List[float]) -> None:
        self.v = v

    def tolist(self) -> List[float]:
        return list(self.v)


def test_array_likes_are_taken_by_duck_typing_without_numpy():
    assert encode_value(_Scalar(1.25)) == "1.25"
    assert encode_value(_Scalar(True)) == "true"
    assert encode_value(_Vector([1, 2.5])) == "[1.0, 2.5]"

    class Float64(float):  # numpy.float64 is a float subclass whose repr is not a literal
        def __repr__(self) -> str:
            return f"np.float64({float(self)})"

    assert encode_value(Float64(1.5)) == "1.5"
    assert encode_value([Float64(0.5)]) == "[0.5]"


# ---- every failure is a HuddleError -------------------------------------------------


def _frozen_relay() -> "tuple[socket.socket, int]":
    """A relay that greets and then never answers (a frozen daemon)."""
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    held: List[socket.socket] = []

    def serve() -> None:
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            c.sendall(b"HUDDLE 2 robot 9\n")
            held.append(c)

    threading.Thread(target=serve, daemon=True).start()
    return srv, srv.getsockname()[1]


@pytest.mark.parametrize("flavour", ["sync", "async"])
def test_a_frozen_daemon_times_out_as_a_huddle_error(flavour):
    srv, port = _frozen_relay()
    try:
        if flavour == "sync":
            r: Any = Relay("127.0.0.1", port, timeout=0.3)
        else:
            r = AsyncAdapter("127.0.0.1", port, timeout=0.3)
        t0 = time.monotonic()
        with pytest.raises(HuddleError) as caught:
            r.set("local.var.x", 1)
        assert isinstance(caught.value, RelayTimeout) and isinstance(caught.value, TimeoutError)
        assert time.monotonic() - t0 < 3, "the timeout is the relay's, not longer"
        if flavour == "async":
            r.shutdown()
    finally:
        srv.close()


def test_nobody_there_is_a_huddle_error():
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    port = srv.getsockname()[1]
    srv.close()
    with pytest.raises(HuddleError):
        Relay("127.0.0.1", port, timeout=0.5)


# ---- reconnect after a daemon restart -----------------------------------------------


@pytest.fixture
def solo(tmp_path: Path):
    """One daemon (robot 3) on a group of its own, restartable on the same port."""
    group = scratch_group()
    holder = {"d": start_daemon(3, group, tmp_path)}

    def restart() -> None:
        port = holder["d"].port
        holder["d"].stop()
        holder["d"] = start_daemon(3, group, tmp_path, port=port)

    holder["restart"] = restart  # type: ignore[assignment]
    yield holder
    holder["d"].stop()


def test_requests_and_watches_survive_a_daemon_restart(solo, connect):
    r = connect(solo["d"].port)
    r.set("local.var.mode", "attack")
    w = r.watch("local.var.mode", events=True, timeout=10)
    first = next(w)
    assert isinstance(first, Binding) and first.value == "attack"
    solo["restart"]()
    # The first request after the restart goes through on a new connection.
    r.set("local.var.mode", "defend")
    assert r.get("local.var.mode").value == "defend"
    # The watch connects again, says so, and starts again from the current value.
    seen = []
    for item in w:
        seen.append(item)
        if isinstance(item, Binding) and item.value == "defend":
            break
    assert any(isinstance(i, Reconnected) and i.robot == 3 for i in seen), seen
    w.close()


def test_without_reconnect_a_restart_is_a_connection_error(solo):
    r = Relay("127.0.0.1", solo["d"].port, reconnect=False)
    solo["restart"]()
    with pytest.raises(RelayConnectionError):
        r.set("local.var.x", 1)
    r.close()


# ---- staleness, departure, join and leave on push watches ---------------------------


@pytest.fixture
def pair(tmp_path: Path):
    group = scratch_group()
    a = start_daemon(4, group, tmp_path)
    b = start_daemon(5, group, tmp_path)
    yield a, b
    a.stop()
    b.stop()


def test_a_dead_robots_value_on_a_push_watch_turns_departed_and_ages(pair, connect):
    a, b = pair
    ra, rb = connect(a.port), connect(b.port)
    ra.set("*.var.ball", [1.0, 2.0])
    w = rb.watch("4.var.#", events=True, timeout=5)
    items = [next(w), next(w)]
    assert items[0] == Joined(4), items
    assert isinstance(items[1], Binding) and items[1].value == [1.0, 2.0]
    assert not items[1].departed
    a.proc.kill()  # robot 4 dies without a word
    t0 = time.monotonic()
    left = next(w)
    again = next(w)
    assert left == Left(4), left
    assert isinstance(again, Binding) and again.key == "4.var.ball" and again.departed, again
    assert again.age_ms >= items[1].age_ms + 200, f"a dead robot's value is not young: {again.age_ms} ms"
    assert time.monotonic() - t0 < 3, "noticed within a few probe periods"
    latest = w.latest()["4.var.ball"]
    time.sleep(0.2)
    assert latest.departed and latest.age_now_ms >= again.age_ms + 150, "it keeps ageing"
    w.close()


def test_a_robot_that_comes_back_joins_again(pair, connect, tmp_path):
    a, b = pair
    ra, rb = connect(a.port), connect(b.port)
    ra.set("*.var.alive", 1)
    w = rb.watch("4.var.#", events=True, timeout=8)
    assert next(w) == Joined(4)
    next(w)
    a.stop()
    assert next(w) == Left(4)
    next(w)  # the departed value
    # Robot 4 again, on the same group.
    proc_args = a.proc.args
    group = proc_args[proc_args.index("--group") + 1]
    a2 = start_daemon(4, group, tmp_path)
    try:
        r2 = Relay("127.0.0.1", a2.port)
        r2.set("*.var.alive", 2)
        rest = []
        for item in w:
            rest.append(item)
            if isinstance(item, Binding) and item.value == 2:
                break
        assert Joined(4) in rest, rest
        r2.close()
    finally:
        a2.stop()
    w.close()


# ---- keys, snapshot, stats ----------------------------------------------------------


def test_keys_hide_the_daemons_counters_unless_asked(team, connect):
    r = connect(team.a.port)
    r.set("local.var.keys_demo", 1)
    r.set("*.var.keys_demo", 2)
    keys = r.keys()
    assert "local.var.keys_demo" in keys and "1.var.keys_demo" in keys, keys
    assert not [k for k in keys if k.startswith("local.var.huddle.")], keys
    everything = r.keys(internal=True)
    assert any(k.startswith("local.var.huddle.stats.") for k in everything)
    assert r.keys("1.var.keys_demo") == ["1.var.keys_demo"]
    assert r.keys("9.var.#") == []
    # The connection carries on as before.
    assert r.get("local.var.keys_demo").value == 1


def test_stats_are_the_daemons_counters_by_name(team, connect):
    r = connect(team.a.port)
    stats = r.stats()
    assert stats, "the daemon publishes counters"
    assert all(not k.startswith("local.") for k in stats), list(stats)[:5]
    assert all(isinstance(v, (int, float, bool, str)) for v in stats.values())


# ---- callbacks ----------------------------------------------------------------------


def test_subscribe_calls_back_on_a_thread(team):
    got: List[Any] = []
    done = threading.Event()

    def on_update(item: Any) -> None:
        got.append(item)
        if isinstance(item, Binding) and item.value == 3:
            done.set()

    with Relay("127.0.0.1", team.a.port) as r:
        sub = r.subscribe("local.var.cb", on_update)
        for i in (1, 2, 3):
            r.set("local.var.cb", i)
        assert done.wait(5), got
        sub.close()
        assert sub.error is None
    assert [b.value for b in got if isinstance(b, Binding)][-1] == 3


def test_async_subscribe_calls_back_on_a_task(team):
    async def main() -> List[Any]:
        got: List[Any] = []
        async with AsyncRelay("127.0.0.1", team.a.port) as r:
            done = asyncio.Event()

            async def on_update(item: Any) -> None:
                got.append(item)
                if isinstance(item, Binding) and item.value == "c":
                    done.set()

            sub = r.subscribe("local.var.acb", on_update)
            await asyncio.sleep(0.1)
            for v in ("a", "b", "c"):
                await r.set("local.var.acb", v)
            await asyncio.wait_for(done.wait(), 5)
            await sub.close()
        return got

    got = asyncio.run(main())
    assert got[-1].value == "c"


# ---- the team layer's typed keys ----------------------------------------------------


def test_team_layer_values_follow_the_contract():
    assert pose_value(1, 2, 0.5, [0.1, 0.0, 0.0, 0.2, 0.0, 0.05]) == [
        1.0, 2.0, 0.5, 0.1, 0.0, 0.0, 0.2, 0.0, 0.05
    ]
    full = [[0.1, 0.01, 0.0], [0.01, 0.2, 0.0], [0.0, 0.0, 0.05]]
    assert pose_value(0, 0, 0, full, age_s=0.1)[3:] == [0.1, 0.01, 0.0, 0.2, 0.0, 0.05, 0.1]
    assert ball_value(1.5, -0.5, [0.04, 0.0, 0.04]) == [1.5, -0.5, 0.04, 0.0, 0.04]
    with pytest.raises(ValueError, match="symmetric"):
        ball_value(0, 0, [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="3 values"):
        ball_value(0, 0, [1.0, 2.0])
    ball = team_ball_of(
        Binding("local.var.team.ball", "floats", [1, 2, 0.5, 0, 0.1, 0, 0.1, 0.9, 0.2], 40, 1)
    )
    assert ball == TeamBall(1, 2, 0.5, 0, 0.1, 0, 0.1, 0.9, 0.2, read_age_ms=40)
    mates = mates_of(Binding("local.var.team.mates", "floats", [2, 1, 1, 0, 0.1, 3, -1, 0, 3.1, 2.5], 0, 1))
    assert [(m.robot, m.silent_s) for m in mates] == [(2, 0.1), (3, 2.5)]
    assert team_ball_of(None) is None


@needs_numpy
def test_team_layer_helpers_take_numpy_and_write_the_contracts_keys(team, connect):
    r = connect(team.a.port)
    r.set_pose(np.float64(1.0), 2.0, 0.25, np.diag([0.1, 0.1, 0.02]))
    b = r.get("local.var.robot.pose")
    assert b.value == [1.0, 2.0, 0.25, 0.1, 0.0, 0.0, 0.1, 0.0, 0.02]
    r.ball_seen(1.5, 0.0, np.eye(2) * 0.04, age_s=0.05)
    assert r.get("local.var.robot.ball").value == [1.5, 0.0, 0.04, 0.0, 0.04, 0.05]
    r.kicked(math.pi / 2, 3.0)
    assert r.get("local.var.robot.kick").value == [math.pi / 2, 3.0]
