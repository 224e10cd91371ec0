"""huddle_client: talk to a huddle daemon's relay from Python.

A huddle daemon (``huddle daemon``) replicates a robot team's blackboard over UDP
multicast and serves it on a TCP line protocol (the relay, port 2001). This package
speaks that protocol, with no dependencies:

- :class:`Relay` (blocking) and :class:`AsyncRelay` (asyncio): ``set``, ``get``,
  ``watch``, ``post``;
- :class:`Binding`: a value with its key, type, age and owner;
- :class:`RelayError` (``.code``, ``.text``) for the relay's ``ERR`` answers,
  :class:`TalkLost` for talk messages the team could not recover,
  :class:`RelayConnectionError` when the daemon is not there.
"""

from ._async import AsyncRelay, AsyncWatch
from ._protocol import (
    Binding,
    HuddleError,
    RelayConnectionError,
    RelayError,
    TalkLost,
    Value,
    decode_value,
    encode_value,
    parse_lost,
)
from ._sync import Relay, Watch

__version__ = "0.1.0"

__all__ = [
    "AsyncRelay",
    "AsyncWatch",
    "Binding",
    "HuddleError",
    "Relay",
    "RelayConnectionError",
    "RelayError",
    "TalkLost",
    "Value",
    "Watch",
    "decode_value",
    "encode_value",
    "parse_lost",
]
