"""huddle_client: talk to a huddle daemon's relay from Python.

A huddle daemon (``huddle daemon``) replicates a robot team's blackboard over UDP
multicast and serves it on a TCP line protocol (the relay, port 2001). This package
speaks that protocol, with no dependencies:

- :class:`Relay` (blocking) and :class:`AsyncRelay` (asyncio): ``set``, ``get``,
  ``watch`` (or ``subscribe`` with a callback), ``post``, ``keys``, ``snapshot``,
  ``stats``, and the team layer's typed keys (``set_pose``, ``ball_seen``,
  ``team_ball``, ...); they reconnect by themselves after a daemon restart;
- numpy scalars and 1-D arrays are taken as values (by duck typing: numpy is not
  needed);
- :class:`Binding`: a value with its key, type, age and owner;
- :class:`RelayError` (``.code``, ``.text``) for the relay's ``ERR`` answers,
  :class:`TalkLost` for talk messages the team could not recover,
  :class:`RelayConnectionError` when the daemon is not there, :class:`RelayTimeout`
  when it does not answer: all :class:`HuddleError`;
- :class:`Joined`, :class:`Left`, :class:`Reconnected`: watch events (``events=True``).
"""

from ._async import AsyncRelay, AsyncWatch
from ._protocol import (
    Binding,
    Event,
    HuddleError,
    Joined,
    Left,
    Reconnected,
    RelayConnectionError,
    RelayError,
    RelayTimeout,
    TalkLost,
    Value,
    decode_value,
    encode_value,
    parse_lost,
    plain_value,
)
from ._team import Mate, OwnBall, Pose, TeamBall
from ._sync import Relay, Watch

__version__ = "0.1.0"

__all__ = [
    "AsyncRelay",
    "AsyncWatch",
    "Binding",
    "Event",
    "HuddleError",
    "Joined",
    "Left",
    "Mate",
    "OwnBall",
    "Pose",
    "Reconnected",
    "RelayTimeout",
    "TeamBall",
    "Relay",
    "RelayConnectionError",
    "RelayError",
    "TalkLost",
    "Value",
    "Watch",
    "decode_value",
    "encode_value",
    "parse_lost",
    "plain_value",
]
