"""The package README's examples, run as written (only the ports changed) against the
test daemons: a program written from the README works."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from conftest import PACKAGE_DIR


def readme_blocks() -> list:
    text = (PACKAGE_DIR / "README.md").read_text(encoding="utf-8")
    return re.findall(r"```python\n(.*?)```", text, re.S)


def run(code: str) -> subprocess.CompletedProcess:  # type: ignore[type-arg]
    env = dict(os.environ, PYTHONPATH=str(PACKAGE_DIR))
    return subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=30
    )


def test_the_readme_example_drives_two_daemons(team):
    example = readme_blocks()[0]
    assert "2001" in example and "2002" in example
    code = example.replace("2001", str(team.a.port)).replace("2002", str(team.b.port))
    out = run(code)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("1.var.ball.dist 1.5 ") and lines[0].endswith("owner 1"), lines
    assert lines[1].startswith("Binding(key='1.var.ball.dist', type='float', value=1.5"), lines
    assert lines[2] == "robot 2 heard kick-off", lines
    assert lines[3].startswith("refused: 420 "), lines


def block_with(marker: str) -> str:
    found = [b for b in readme_blocks() if marker in b]
    assert len(found) == 1, f"one README example with {marker!r}"
    return found[0]


def test_the_readme_asyncio_example_runs(team):
    example = block_with("asyncio.run")
    out = run(example.replace("2001", str(team.a.port)))
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("Binding(key='1.var.ball.dist'"), out.stdout


def test_the_readme_numpy_example_runs(team):
    pytest.importorskip("numpy")
    out = run(block_with("np.array([0.33").replace("2001", str(team.a.port)))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[ 0.66 -4.5 ]", out.stdout


def test_the_readme_team_layer_example_runs(team):
    pytest.importorskip("numpy")
    out = run(block_with("set_pose").replace("2001", str(team.a.port)))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("pose written: [1.0, -0.5, 0.3]"), out.stdout
