"""The client against two real daemons on loopback; each test runs twice, with the
blocking Relay and with AsyncRelay (see ``conftest.connect``)."""

from __future__ import annotations

import math
import socket
import threading
import time
from fractions import Fraction
from typing import Any, Callable, List

import pytest

from conftest import start_daemon
from huddle_client import Binding, RelayConnectionError, RelayError, TalkLost


def wait_for(read: Callable[[], Any], within: float = 5.0) -> Any:
    deadline = time.monotonic() + within
    while True:
        got = read()
        if got is not None:
            return got
        assert time.monotonic() < deadline, "still nothing"
        time.sleep(0.02)


def test_the_greeting_names_the_robot(team, connect):
    assert connect(team.a.port).robot == 1
    assert connect(team.b.port).robot == 2


@pytest.mark.parametrize(
    "value, type_name",
    [
        (42, "int"),
        (-(2**63), "int"),
        (2**63 - 1, "int"),
        (1.5, "float"),
        (-0.0, "float"),
        (1e300, "float"),
        (0.1, "float"),
        (float("inf"), "float"),
        (True, "bool"),
        (False, "bool"),
        ('say "hi"\n\tand \\ then \x01 é ⚽', "string"),
        ("", "string"),
        (b"\x00\x01\xfe\xff", "bytes"),
        (b"", "bytes"),
        ([1.5, -2.0, 0.25], "floats"),
        ([], "floats"),
    ],
)
def test_every_type_round_trips_exactly(team, connect, value, type_name):
    r = connect(team.a.port)
    r.set("local.var.roundtrip", value)
    b = r.get("local.var.roundtrip")
    assert isinstance(b, Binding)
    assert (b.key, b.type, b.owner) == ("local.var.roundtrip", type_name, 1)
    assert b.value == value and type(b.value) is type(value)
    if isinstance(value, float):
        assert math.copysign(1, b.value) == math.copysign(1, value)


def test_nan_and_lists_of_ints_and_tuples(team, connect):
    r = connect(team.a.port)
    r.set("local.var.nan", float("nan"))
    assert math.isnan(r.get("local.var.nan").value)
    r.set("local.var.ints", (1, -2, 2**24))
    assert r.get("local.var.ints").value == [1.0, -2.0, float(2**24)]
    # Whatever width the relay keeps float lists in, nothing is narrowed: the list comes
    # back exactly, or the client refuses it before sending.
    wide = [2.0**53 + 2, 0.1, 1e300, 123456789.123]
    try:
        r.set("local.var.wide", wide)
    except ValueError as e:
        assert "32-bit" in str(e)
        assert r.get("local.var.wide") is None
    else:
        assert r.get("local.var.wide").value == wide
    r.set("local.var.ba", bytearray(b"ab"))
    assert r.get("local.var.ba").value == b"ab"


@pytest.mark.parametrize(
    "value, error",
    [
        (None, TypeError),
        ({"a": 1}, TypeError),
        ({1, 2}, TypeError),
        ([[1.0]], TypeError),
        ([True, 1.0], TypeError),
        (["1"], TypeError),
        (2**63, ValueError),
        (-(2**63) - 1, ValueError),
        ([2**53 + 1], ValueError),
        ([Fraction(1, 3)], ValueError),
        ("\ud800", ValueError),
    ],
)
def test_a_value_that_cannot_be_represented_raises_and_nothing_is_sent(
    team, connect, value, error
):
    r = connect(team.a.port)
    with pytest.raises(error):
        r.set("local.var.unsendable", value)
    assert r.get("local.var.unsendable") is None, "nothing was written"
    r.set("local.var.after", 1)
    assert r.get("local.var.after").value == 1, "the connection is still good"


def test_a_value_crosses_robots_with_its_age_and_owner(team, connect):
    a, b = connect(team.a.port), connect(team.b.port)
    a.set("*.var.ball.dist", 2.25)
    got = wait_for(lambda: b.get("1.var.ball.dist"))
    assert (got.key, got.type, got.value, got.owner) == ("1.var.ball.dist", "float", 2.25, 1)
    assert 0 <= got.age_ms < 2000
    time.sleep(0.3)
    later = b.get("1.var.ball.dist")
    assert later.age_ms >= got.age_ms + 200, "the age grows on the reader's clock"
    newest = b.get("*.var.ball.dist")
    assert newest.key == "1.var.ball.dist", "a * read names the copy that answered"


def test_a_departed_robot_s_values_are_flagged(team, connect):
    r = connect(team.b.port)
    if r.version < 2:
        pytest.skip("the relay flags departed owners from protocol 2 on")
    third = start_daemon(3, team.group, team.config_dir)
    try:
        c = connect(third.port)
        c.set("*.var.alive", True)
        got = wait_for(lambda: r.get("3.var.alive"))
        assert not got.departed
    finally:
        third.stop()
    wait_for(lambda: r.get("3.var.alive") if r.get("3.var.alive").departed else None)


def test_get_with_a_maximum_age(team, connect):
    r = connect(team.a.port)
    if r.version < 2:
        pytest.skip("GETV key max_age_ms is protocol 2")
    r.set("local.var.aging", 1)
    time.sleep(0.15)
    with pytest.raises(RelayError) as e:
        r.get("local.var.aging", max_age_ms=50)
    assert e.value.code == 406
    assert r.get("local.var.aging", max_age_ms=60_000).value == 1


def test_an_unknown_key_reads_as_none(team, connect):
    assert connect(team.b.port).get("7.var.never.set") is None


def test_errors_carry_the_relay_s_code_and_text(team, connect):
    r = connect(team.b.port)
    with pytest.raises(RelayError) as e:
        r.set("1.var.x", 1)
    assert e.value.code == 420 and "1.var.x" in e.value.text
    with pytest.raises(RelayError) as e:
        r.set("*.var.a..b", 1)
    assert e.value.code == 410 and e.value.text
    with pytest.raises(RelayError) as e:
        r.get("*.talk.plan")
    assert e.value.code == 421
    with pytest.raises(RelayError) as e:
        r.set("*.var.big", "x" * 5000)
    assert e.value.code == 402, "a line over 4 KiB"
    with pytest.raises(RelayError) as e:
        r.watch("2.var.#.x")
    assert e.value.code == 411
    with pytest.raises(RelayError) as e:
        r.set("local.var.team.goer", 2)
    assert e.value.code == 423 and "team layer" in e.value.text, "the team layer's own output"
    with pytest.raises(RelayError) as e:
        r.set("local.var.huddle.stats.frames_in", 0)
    assert e.value.code == 423, "the daemon's counters"
    with pytest.raises(ValueError):
        r.watch("x", interval_ms=-1)
    r.set("*.var.fine", 3)
    assert r.get("2.var.fine").value == 3, "errors do not end the session"


def test_watch_pushes_each_change_as_it_happens(team, connect):
    a, b = connect(team.a.port), connect(team.b.port)
    a.set("*.var.counter.n", 0)
    wait_for(lambda: b.get("1.var.counter.n"))
    seen: List[int] = []
    with b.watch("1.var.counter.+", timeout=5) as w:
        first = next(w)
        assert first.key == "1.var.counter.n", "the current value comes first"
        for i in range(1, 6):
            a.set("*.var.counter.n", i)
            while True:
                u = next(w)
                if u.value == i:
                    seen.append(u.value)
                    assert u.owner == 1 and u.age_ms < 1000
                    break
    assert seen == [1, 2, 3, 4, 5]


def test_a_periodic_watch_repeats_every_interval(team, connect):
    a, b = connect(team.a.port), connect(team.b.port)
    a.set("local.var.periodic", 7)
    with a.watch(["local.var.periodic", "local.var.nothing.#"], interval_ms=100, timeout=5) as w:
        t0 = time.monotonic()
        updates = [next(w) for _ in range(4)]
        took = time.monotonic() - t0
    assert all(u.key == "local.var.periodic" and u.value == 7 for u in updates)
    assert updates[-1].age_ms >= updates[0].age_ms + 250
    assert 0.25 <= took < 3.0


def test_posts_arrive_in_order_at_a_watcher(team, connect):
    a, b = connect(team.a.port), connect(team.b.port)
    with b.watch("+.talk.plan", timeout=5) as w:
        time.sleep(0.2)
        for i in range(10):
            a.post("plan", f"step {i}")
        got = [next(w) for _ in range(10)]
    assert [m.value for m in got] == [f"step {i}" for i in range(10)]
    assert all(m.is_talk and m.key == "1.talk.plan" and m.owner == 1 for m in got)
    with pytest.raises(RelayError) as e:
        b.post("1.talk.plan", 1)
    assert e.value.code == 421, "only own queues can be posted to"


def test_a_watch_is_closed_with_its_relay(team, connect):
    r = connect(team.a.port)
    r.set("local.var.closing", 1)
    w = r.watch("local.var.closing", timeout=5)
    assert next(w).value == 1
    r.close()
    assert r.closed
    with pytest.raises(StopIteration):
        next(w)


def test_an_absent_daemon_is_a_connection_error(connect):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # bound, not listening: refused
        with pytest.raises(RelayConnectionError):
            connect(port, timeout=2)


class FakeRelay:
    """A relay that answers ADDW/REFR and then plays a script of pushed lines: the
    `LOST` lines a daemon sends when talk messages are given up."""

    def __init__(self, pushed: List[str]) -> None:
        self.pushed = pushed
        self.server = socket.socket()
        self.server.bind(("127.0.0.1", 0))
        self.server.listen()
        self.port = self.server.getsockname()[1]
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.server.accept()
            except OSError:
                return
            threading.Thread(target=self._session, args=(conn,), daemon=True).start()

    def _session(self, conn: socket.socket) -> None:
        with conn:
            conn.sendall(b"HUDDLE 1 robot 2\n")
            f = conn.makefile("rb")
            for raw in f:
                line = raw.decode().strip()
                if line == "QUIT":
                    conn.sendall(b"BYE\n")
                    return
                conn.sendall(b"OK\n")
                if line.startswith("REFR"):
                    conn.sendall("".join(p + "\n" for p in self.pushed).encode())

    def close(self) -> None:
        self.server.close()


SCRIPT = [
    'UPD 3.talk.plan string "one" 0',
    "LOST 3.talk.plan 4 6",
    'UPD 3.talk.plan string "seven" 0',
]


def test_flags_after_the_age_are_read_and_unknown_ones_skipped(connect):
    fake = FakeRelay(["UPD 3.var.x int 1 500 departed", 'UPD 3.var.y string "a 1" 5 shiny'])
    try:
        with connect(fake.port).watch("3.var.+", timeout=5) as w:
            x, y = next(w), next(w)
        assert (x.value, x.age_ms, x.departed) == (1, 500, True)
        assert (y.value, y.age_ms, y.departed) == ("a 1", 5, False)
    finally:
        fake.close()


def test_a_lost_line_raises_talk_lost_and_the_watch_goes_on(connect):
    fake = FakeRelay(SCRIPT)
    try:
        r = connect(fake.port)
        w = r.watch("+.talk.plan", timeout=5)
        assert next(w).value == "one"
        with pytest.raises(TalkLost) as e:
            next(w)
        lost = e.value
        assert (lost.queue, lost.sender, lost.first, lost.last, lost.count) == (
            "3.talk.plan", 3, 4, 6, 3
        )
        assert lost.line == "LOST 3.talk.plan 4 6"
        assert next(w).value == "seven", "the watch carries on after a loss"
    finally:
        fake.close()


def test_lost_lines_can_come_as_events(connect):
    fake = FakeRelay(SCRIPT)
    try:
        r = connect(fake.port)
        with r.watch("+.talk.plan", timeout=5, lost="event") as w:
            got = [next(w) for _ in range(3)]
        assert isinstance(got[1], TalkLost) and got[1].count == 3
        assert [g.value for g in (got[0], got[2])] == ["one", "seven"]
    finally:
        fake.close()
