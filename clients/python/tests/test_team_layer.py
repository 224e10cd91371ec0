"""The team layer in three real daemons, fed only through the relay (docs/team-layer.md)."""

from __future__ import annotations

import subprocess
import sys

from conftest import PACKAGE_DIR, scratch_group, start_daemon
from huddle_client import Relay, RelayError


def test_three_daemons_fed_by_the_readme_example_agree_on_the_team_ball(tmp_path):
    # Robot 1 sees the ball 1.5 m ahead of (-1, 0): at (0.5, 0). Robots 2 and 3 never see
    # it: their team ball can only come from robot 1's world model over the network.
    group = scratch_group()
    daemons = [start_daemon(r, group, tmp_path) for r in (1, 2, 3)]
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
