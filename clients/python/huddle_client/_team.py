"""Typed helpers for the team layer (``docs/team-layer.md``): what a robot program
writes to ``local.var.robot.*`` and reads from ``local.var.team.*``, as Python values.

Frames follow REP-103 (field origin at the centre spot, +x towards the opponent goal,
+y left, θ counter-clockwise); units are metres, radians, seconds. Covariances are given
as a full matrix (nested lists or a 2-D numpy array) or as their upper triangle row by
row (``var_x, cov_xy, var_y`` for 2-D). A value the layer refuses raises
:class:`RelayError` 412 saying why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, List, Optional, Sequence

from ._protocol import Binding, plain_value

#: The keys of the team layer's contract.
POSE = "local.var.robot.pose"
ODOMETRY = "local.var.robot.odometry"
LANDMARKS = "local.var.robot.landmarks"
BALL = "local.var.robot.ball"
KICK = "local.var.robot.kick"
GOAL_IN_VIEW = "local.var.robot.goal_in_view"
COST = "local.var.robot.cost"
GOALKEEPER = "local.var.robot.goalkeeper"
FALLEN = "local.var.robot.fallen"
BALL_RESET = "local.var.robot.ball_reset"
WHISTLE = "local.var.robot.whistle"
TEAM_BALL = "local.var.team.ball"
TEAM_GOER = "local.var.team.goer"
TEAM_GOING = "local.var.team.going"
TEAM_MATES = "local.var.team.mates"
TEAM_OWN_BALL = "local.var.team.own_ball"
TEAM_POSE = "local.var.team.pose"
TEAM_BUDGET = "local.var.team.budget"


def upper_triangle(cov: Any, n: int) -> List[float]:
    """A covariance as its upper triangle, row by row: from an ``n``×``n`` matrix
    (nested sequences or a 2-D array, which must be symmetric) or from the
    ``n(n+1)/2`` values already in that order."""
    if hasattr(cov, "tolist"):
        cov = cov.tolist()
    rows = list(cov)
    if rows and all(isinstance(plain_value(r), (list, tuple)) for r in rows):
        m = [[float(x) for x in plain_value(r)] for r in rows]  # type: ignore[union-attr]
        if len(m) != n or any(len(r) != n for r in m):
            raise ValueError(f"a covariance here is {n}x{n}, not {len(m)}x{len(m[0])}")
        for i in range(n):
            for j in range(i):
                if not math.isclose(m[i][j], m[j][i], rel_tol=1e-9, abs_tol=1e-12):
                    raise ValueError(f"covariance is not symmetric at ({i}, {j})")
        return [m[i][j] for i in range(n) for j in range(i, n)]
    flat = [float(plain_value(x)) for x in rows]  # type: ignore[arg-type]
    if len(flat) != n * (n + 1) // 2:
        raise ValueError(
            f"a {n}x{n} covariance is {n * (n + 1) // 2} values (upper triangle) or a "
            f"{n}x{n} matrix, not {len(flat)} values"
        )
    return flat


def _with_age(values: List[float], age_s: Optional[float]) -> List[float]:
    return values if age_s is None else values + [float(age_s)]


def pose_value(x: float, y: float, theta: float, cov: Any, age_s: Optional[float] = None) -> List[float]:
    """``local.var.robot.pose``: ``[x, y, θ, upper triangle of the 3×3 covariance]``."""
    return _with_age([float(x), float(y), float(theta)] + upper_triangle(cov, 3), age_s)


def ball_value(x: float, y: float, cov: Any, age_s: Optional[float] = None) -> List[float]:
    """``local.var.robot.ball``: ``[x, y, var_x, cov_xy, var_y]`` in the robot frame."""
    return _with_age([float(x), float(y)] + upper_triangle(cov, 2), age_s)


def kick_value(direction: float, speed: float, contact_prob: Optional[float] = None) -> List[float]:
    v = [float(direction), float(speed)]
    return v if contact_prob is None else v + [float(contact_prob)]


def landmarks_value(sightings: Iterable[Sequence[float]]) -> List[float]:
    out: List[float] = []
    for i, s in enumerate(sightings):
        row = [float(plain_value(v)) for v in plain_value(s)]  # type: ignore[union-attr, arg-type]
        if len(row) != 6:
            raise ValueError(
                f"landmark {i}: 6 values (field_x, field_y, range, bearing, sigma_range, "
                f"sigma_bearing), not {len(row)}"
            )
        out += row
    return out


@dataclass(frozen=True)
class TeamBall:
    """The team ball (``local.var.team.ball``), field frame. ``confidence`` is the
    global ball confidence (0-1); ``age_s`` the age of the newest sighting in it, as
    written; ``read_age_ms`` the age of the value itself when read."""

    x: float
    y: float
    vx: float
    vy: float
    var_x: float
    cov_xy: float
    var_y: float
    confidence: float
    age_s: float
    read_age_ms: int = 0


@dataclass(frozen=True)
class OwnBall:
    """This robot's own ball estimate (``local.var.team.own_ball``), field frame."""

    x: float
    y: float
    vx: float
    vy: float
    var_x: float
    cov_xy: float
    var_y: float
    age_s: float


@dataclass(frozen=True)
class Pose:
    """A pose in the field frame with its covariance's upper triangle
    (``var_x, cov_xy, cov_xθ, var_y, cov_yθ, var_θ``)."""

    x: float
    y: float
    theta: float
    cov: List[float]


@dataclass(frozen=True)
class Mate:
    """A teammate as this robot's team layer holds it (``local.var.team.mates``)."""

    robot: int
    x: float
    y: float
    theta: float
    silent_s: float


def _floats(b: Optional[Binding], n: int, key: str) -> Optional[List[float]]:
    if b is None:
        return None
    if isinstance(b.value, list) and len(b.value) == 0:
        # ``[]``: the layer had one and has none now (forgotten at a kick-off).
        return None
    if not isinstance(b.value, list) or len(b.value) < n:
        raise ValueError(f"{key}: expected at least {n} floats, got {b.value!r}")
    return b.value


def team_ball_of(b: Optional[Binding]) -> Optional[TeamBall]:
    v = _floats(b, 9, TEAM_BALL)
    if v is None or b is None:
        return None
    return TeamBall(*v[:9], read_age_ms=b.age_ms)


def own_ball_of(b: Optional[Binding]) -> Optional[OwnBall]:
    v = _floats(b, 8, TEAM_OWN_BALL)
    return None if v is None else OwnBall(*v[:8])


def pose_of(b: Optional[Binding]) -> Optional[Pose]:
    v = _floats(b, 9, TEAM_POSE)
    return None if v is None else Pose(v[0], v[1], v[2], list(v[3:9]))


def mates_of(b: Optional[Binding]) -> List[Mate]:
    v = _floats(b, 0, TEAM_MATES)
    if not v:
        return []
    return [
        Mate(int(v[i]), v[i + 1], v[i + 2], v[i + 3], v[i + 4])
        for i in range(0, len(v) - len(v) % 5, 5)
    ]


class TeamMixin:
    """The team layer's keys as methods of :class:`~huddle_client.Relay`."""

    def set(self, key: str, value: object) -> None:  # pragma: no cover - Relay's
        raise NotImplementedError

    def get(self, key: str, max_age_ms: Optional[int] = None) -> Optional[Binding]:  # pragma: no cover
        raise NotImplementedError

    def set_pose(self, x: float, y: float, theta: float, cov: Any, age_s: Optional[float] = None) -> None:
        """This robot's pose estimate (field frame, 3×3 covariance of x, y, θ)."""
        self.set(POSE, pose_value(x, y, theta, cov, age_s))

    def odometry(self, forward: float, left: float, turn: float) -> None:
        """Motion since the previous odometry write, robot frame (m, m, rad)."""
        self.set(ODOMETRY, [float(forward), float(left), float(turn)])

    def landmarks_seen(self, sightings: Iterable[Sequence[float]]) -> None:
        """Landmarks seen now: each ``(field_x, field_y, range, bearing, sigma_range,
        sigma_bearing)``."""
        self.set(LANDMARKS, landmarks_value(sightings))

    def ball_seen(self, x: float, y: float, cov: Any, age_s: Optional[float] = None) -> None:
        """One ball sighting in the robot frame (2×2 covariance); call it when the
        camera sees the ball, not otherwise."""
        self.set(BALL, ball_value(x, y, cov, age_s))

    def kicked(self, direction: float, speed: float, contact_prob: Optional[float] = None) -> None:
        """A kick just made: field-frame direction (rad), ball speed (m/s)."""
        self.set(KICK, kick_value(direction, speed, contact_prob))

    def set_goal_in_view(self, in_view: bool) -> None:
        self.set(GOAL_IN_VIEW, bool(in_view))

    def set_cost(self, cost: float) -> None:
        """This robot's should-I-go cost, replacing the layer's own."""
        self.set(COST, float(cost))

    def set_goalkeeper(self, goalkeeper: bool) -> None:
        self.set(GOALKEEPER, bool(goalkeeper))

    def set_fallen(self, fallen: bool) -> None:
        self.set(FALLEN, bool(fallen))

    def ball_reset(self) -> None:
        """The referee put the ball back (a kick-off): the layer forgets the ball it tracked."""
        self.set(BALL_RESET, True)

    def whistle(self) -> None:
        """The program heard the referee's whistle now: under GameController3 (whose
        packets show play and goals 15 s late) it starts play in Set, and is a goal in
        play (see docs/team-layer.md)."""
        self.set(WHISTLE, True)

    def team_ball(self) -> Optional[TeamBall]:
        """The team ball now, or ``None`` until some robot saw the ball (and
        again after a kick-off's ``ball_reset``, until somebody sees it)."""
        return team_ball_of(self.get(TEAM_BALL))

    def own_ball(self) -> Optional[OwnBall]:
        return own_ball_of(self.get(TEAM_OWN_BALL))

    def team_pose(self) -> Optional[Pose]:
        """The pose the team layer holds for this robot."""
        return pose_of(self.get(TEAM_POSE))

    def goer(self) -> Optional[int]:
        """The robot going to the ball (``None``: none, or no team layer)."""
        b = self.get(TEAM_GOER)
        return None if b is None or not b.value else int(b.value)  # type: ignore[arg-type]

    def going(self) -> bool:
        """Whether this robot goes to the ball."""
        b = self.get(TEAM_GOING)
        return b is not None and b.value is True

    def mates(self) -> List[Mate]:
        """Teammates' poses from their messages, and how long each has been silent."""
        return mates_of(self.get(TEAM_MATES))

    def budget(self) -> Optional[int]:
        """Messages this robot may still send now under its budget (``None``: none)."""
        b = self.get(TEAM_BUDGET)
        return None if b is None else int(b.value)  # type: ignore[arg-type]


class AsyncTeamMixin:
    """The team layer's keys as coroutines of :class:`~huddle_client.AsyncRelay`; see
    :class:`TeamMixin`."""

    async def set(self, key: str, value: object) -> None:  # pragma: no cover - AsyncRelay's
        raise NotImplementedError

    async def get(self, key: str, max_age_ms: Optional[int] = None) -> Optional[Binding]:  # pragma: no cover
        raise NotImplementedError

    async def set_pose(self, x: float, y: float, theta: float, cov: Any, age_s: Optional[float] = None) -> None:
        await self.set(POSE, pose_value(x, y, theta, cov, age_s))

    async def odometry(self, forward: float, left: float, turn: float) -> None:
        await self.set(ODOMETRY, [float(forward), float(left), float(turn)])

    async def landmarks_seen(self, sightings: Iterable[Sequence[float]]) -> None:
        await self.set(LANDMARKS, landmarks_value(sightings))

    async def ball_seen(self, x: float, y: float, cov: Any, age_s: Optional[float] = None) -> None:
        await self.set(BALL, ball_value(x, y, cov, age_s))

    async def kicked(self, direction: float, speed: float, contact_prob: Optional[float] = None) -> None:
        await self.set(KICK, kick_value(direction, speed, contact_prob))

    async def set_goal_in_view(self, in_view: bool) -> None:
        await self.set(GOAL_IN_VIEW, bool(in_view))

    async def set_cost(self, cost: float) -> None:
        await self.set(COST, float(cost))

    async def set_goalkeeper(self, goalkeeper: bool) -> None:
        await self.set(GOALKEEPER, bool(goalkeeper))

    async def set_fallen(self, fallen: bool) -> None:
        await self.set(FALLEN, bool(fallen))

    async def ball_reset(self) -> None:
        await self.set(BALL_RESET, True)

    async def whistle(self) -> None:
        await self.set(WHISTLE, True)

    async def team_ball(self) -> Optional[TeamBall]:
        return team_ball_of(await self.get(TEAM_BALL))

    async def own_ball(self) -> Optional[OwnBall]:
        return own_ball_of(await self.get(TEAM_OWN_BALL))

    async def team_pose(self) -> Optional[Pose]:
        return pose_of(await self.get(TEAM_POSE))

    async def goer(self) -> Optional[int]:
        b = await self.get(TEAM_GOER)
        return None if b is None or not b.value else int(b.value)  # type: ignore[arg-type]

    async def going(self) -> bool:
        b = await self.get(TEAM_GOING)
        return b is not None and b.value is True

    async def mates(self) -> List[Mate]:
        return mates_of(await self.get(TEAM_MATES))

    async def budget(self) -> Optional[int]:
        b = await self.get(TEAM_BUDGET)
        return None if b is None else int(b.value)  # type: ignore[arg-type]
