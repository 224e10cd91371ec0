"""The team layer in three real daemons, fed only through the relay (docs/team-layer.md)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import urllib.request

from conftest import PACKAGE_DIR, free_tcp_port, huddle_bin, scratch_group, start_daemon
from huddle_client import Relay, RelayError


def monitor_state(port: int) -> dict:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/state", timeout=5) as r:
        return json.loads(r.read())


def test_three_daemons_fed_by_the_readme_example_agree_on_the_team_ball(tmp_path):
    # Robot 1 sees the ball 1.5 m ahead of (-1, 0): at (0.5, 0). Robots 2 and 3 never see
    # it: their team ball can only come from robot 1's world model over the network.
    group = scratch_group()
    daemons = [start_daemon(r, group, tmp_path) for r in (1, 2, 3)]
    http = free_tcp_port()
    monitor = subprocess.Popen(
        [huddle_bin(), "monitor", "--group", group, "--iface", "127.0.0.1",
         "--http", f"127.0.0.1:{http}", "-q"],
        stdout=subprocess.DEVNULL,
    )
    try:
        example = PACKAGE_DIR / "examples" / "team_ball.py"
        assert len(example.read_text().splitlines()) <= 40, "the example stays short"
        out = subprocess.run(
            [sys.executable, str(example)] + [str(d.port) for d in daemons],
            capture_output=True, text=True, timeout=60,
            env={"PYTHONPATH": str(PACKAGE_DIR)},
        )
        assert out.returncode == 0, out.stdout + out.stderr
        assert out.stdout.count("team ball at") == 3, out.stdout
        # While robot 1 sees the ball every robot agrees that it goes.
        assert out.stdout.count("goer 1") == 3, out.stdout
        # The monitor (listen-only, on the same group) draws the team the layers publish:
        # three robots where their programs put them, and the team ball.
        deadline = time.monotonic() + 10
        while True:
            state = monitor_state(http)
            robots = {r["id"]: r for r in state.get("robots", [])}
            if len(robots) == 3 and state.get("team_ball") is not None or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert sorted(robots) == [1, 2, 3], f"the monitor draws {sorted(robots)}: {state}"
        assert state["team_ball"] is not None, f"no team ball on the monitor: {state}"
        for r, (x, y) in zip((1, 2, 3), ((-1.0, 0.0), (-3.0, 1.5), (-3.0, -1.5))):
            p = robots[r]["pose"]
            assert abs(p["x"] - x) < 0.05 and abs(p["y"] - y) < 0.05, f"robot {r} drawn at {p}"
        assert robots[1]["ball"] is not None, f"robot 1's own ball is drawn: {robots[1]}"
        for d in daemons:
            with Relay("127.0.0.1", d.port) as relay:
                ball = relay.get("local.var.team.ball")
                assert ball is not None and ball.type == "floats", f"robot {d.robot}: {ball}"
                x, y = ball.value[0], ball.value[1]
                assert abs(x - 0.5) < 0.3 and abs(y) < 0.3, f"robot {d.robot} holds ({x}, {y})"
                mates = relay.get("local.var.team.mates")
                ids = sorted(int(i) for i in mates.value[0::5])
                assert ids == sorted({1, 2, 3} - {d.robot}), f"robot {d.robot} knows {ids}"
    finally:
        monitor.terminate()
        monitor.wait(5)
        for d in daemons:
            d.stop()


def test_bad_team_layer_input_gets_a_relay_error_and_changes_nothing(tmp_path):
    group = scratch_group()
    d = start_daemon(1, group, tmp_path)
    try:
        with Relay("127.0.0.1", d.port) as relay:
            good = [0.0, 0.0, 0.0, 0.01, 0, 0, 0.01, 0, 0.003]
            relay.set("local.var.robot.pose", good)
            bad = {
                "a malformed pose": ("local.var.robot.pose", [1.0, 2.0]),
                "NaN": ("local.var.robot.pose", [float("nan")] + good[1:]),
                "infinity": ("local.var.robot.ball", [float("inf"), 0, 0.01, 0, 0.01]),
                "not positive definite": ("local.var.robot.pose", [0, 0, 0, 0.01, 0.5, 0, 0.01, 0, 0.003]),
                "a time in the future": ("local.var.robot.ball", [1.0, 0, 0.01, 0, 0.01, -0.5]),
                "hours old": ("local.var.robot.ball", [1.0, 0, 0.01, 0, 0.01, 7200.0]),
                "a wrong type": ("local.var.robot.goalkeeper", 3),
            }
            for what, (key, value) in bad.items():
                try:
                    relay.set(key, value)
                except RelayError as e:
                    assert e.code == 412, f"{what}: {e.code} {e.text}"
                    assert key.split(".")[-1] in e.text, f"{what}: the error names the key: {e.text}"
                else:
                    raise AssertionError(f"{what} was accepted")
            pose = relay.get("local.var.robot.pose")
            assert pose is not None and pose.value == good, f"the stored pose changed: {pose}"
    finally:
        d.stop()
