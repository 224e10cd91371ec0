//! The relay: a line protocol over TCP through which any program (Python, C++, a person
//! with `nc`) reads, writes and watches a robot's blackboard (isocrob-2000 §3.2.6).
//!
//! One command per line, ASCII (UTF-8 inside string values), `\n` or `\r\n`; command
//! words are case-insensitive. Watch patterns use MQTT-style wildcards (`+` one level,
//! `#` the rest), because `*` is already a scope.
//!
//! ```text
//! on connect       -> HUDDLE <version> robot <id>          (version 2)
//! GETV key [max_age_ms]
//!                  -> VAL key type value age_ms [departed] | ERR code text
//! SETV key value   -> OK                                   | ERR code text
//! SETP key value   -> OK | ERR   SETV of an item that may spend a league budget's
//!                                priority reserve at once (a goer change, a kick)
//! CLOK secs        -> OK | ERR   the game clock (play left, s) the budget paces over
//! ADDW pattern     -> OK      DELW pattern -> OK     CLRW -> OK
//! LSTW             -> WATCH pattern (one per line), then END
//! REFR ms          -> OK   then every ms: UPD key type value age_ms [departed] for each
//!                          watched key (REFR 0: push each change as it happens)
//! QUIT             -> BYE, connection closed
//! pushed any time  -> UPD n.talk.q type value 0            a watched queue's message
//!                     LOST n.talk.q first last             messages first..=last of
//!                                                          robot n's queue q are lost
//! ```
//!
//! Details the grammar leaves open, as this implementation settles them:
//! - `type` is `int|float|bool|string|floats|bytes`; values use the literal syntax of
//!   [`crate::literal`] (strings double-quoted with escapes; floats parse back to the
//!   same bits).
//! - `age_ms` is whole milliseconds since the value was set, on **this** robot's clock:
//!   for a teammate's value, the time since it arrived plus its frame's transit plus the
//!   age the sender reported (the time since it was set on the sender's clock). The
//!   transit is estimated per frame from the send stamps and echoes teammates' frames
//!   carry (see the crate docs, "Shared time"); until a teammate's first echo returns it
//!   is the replica's `default_transit` (0 unless configured). No client compares two
//!   clocks.
//! - After the age, a line may carry flag words (letters only; clients skip flags they
//!   do not know, as [`Binding::parse`] does). `departed`: the owner has been silent for
//!   longer than the departure limit (300 ms by default), so the value is old news
//!   however young its age; a departed robot's values are released 60 s (by default)
//!   after its departure, and are gone from then on (`ERR 404`), as are the values a
//!   robot's previous life left once it restarted and published again.
//! - `GETV key max_age_ms` answers `ERR 406` instead of a value older than `max_age_ms`
//!   (by the age above); `GETV key` answers whatever age.
//! - `LOST n.talk.q first last`: the relay gave up messages `first..=last` (sequence
//!   numbers, inclusive) of robot n's queue q: they were lost on the network and can no
//!   longer be repaired. Pushed like a watched queue's `UPD` (a watch must match
//!   `n.talk.q`), in order with its messages, whatever `REFR` says. Never silent loss.
//! - Replies name keys as stored: `GETV *.var.x` answers `VAL 3.var.x ...` when robot 3's
//!   copy is the newest, so the owner is always visible.
//! - `REFR` (any period) first pushes every watched binding once, so a client starts from
//!   the current state; with `REFR 0`, `ADDW` does the same for the new pattern.
//!   Bindings matched by several patterns are pushed once.
//! - `SETV` on an own `talk` queue (`*.talk.q`) posts a message. Messages of watched
//!   queues arrive as `UPD n.talk.q type value 0`, as delivered, whatever `REFR` says.
//! - `SETV` follows the library's rules: another robot's `n.var.x` gives `ERR 420`; a new
//!   key beyond the limits (65536 `local` keys, 4096 own globals by default) `ERR 429`;
//!   a post the queue's full retention buffer cannot take `ERR 430`.
//! - The daemon's own keys are read-only to clients: `SETV` or `SETP` of one gives
//!   `ERR 423` naming who writes it, and nothing is written. They are `local.var.team.*`
//!   while the daemon's team layer runs (its outputs), `local.var.gc.*` while its
//!   GameController listener runs (the game's state) and `local.var.huddle.*` (its
//!   counters). A client that wrote them would make the robot's other programs read a
//!   false decision, game state or count; without the part that writes them (`huddle
//!   daemon --no-team-layer`, no listener) the first two are ordinary local keys, for a
//!   program that runs its own. The daemon counts refusals in
//!   `local.var.huddle.stats.relay_read_only_refused`.
//! - `CLOK secs` sets the game clock a league budget paces over, unless the league's
//!   referee system sets it: while a GameController's figures are in force on the robot
//!   (the daemon's listener heard one; its last figure stays in force through a
//!   silence), `CLOK` gets `ERR 424` and the clock is left as the GC's packets set it
//!   (a client's clock would move the pacing line until the GC's next packet). The
//!   daemon counts refusals in `local.var.huddle.stats.relay_clock_refused`.
//! - Keys are ASCII, so a watch pattern that is not (`ADDW *.var.café`) could never
//!   match: `ADDW` and `DELW` refuse it with `ERR 411`, as a key that is not ASCII gets
//!   `ERR 410` in every command. The daemon counts both in
//!   `local.var.huddle.stats.relay_non_ascii_refused`. String values may hold any UTF-8.
//! - Empty lines are ignored. Errors never end a session; see [`ErrCode`] for codes.
//! - `huddle daemon` serves at most `--max-clients` clients at once (64 by default): a
//!   connection beyond gets one line `ERR 503 too many relay clients (N connected,
//!   --max-clients); try again later` in place of the greeting and is closed, counted in
//!   `local.var.huddle.stats.relay_clients_refused`; the clients connected are unaffected.
//! - A line longer than 4 KiB gets `ERR 402` and is discarded up to its end. A client
//!   with more than 1 MiB of unread output is cut off (see [`SessionLimits`]).

mod board;
mod command;
mod error;
mod reply;
mod session;

pub use board::Board;
pub use command::{Command, Rejected, MAX_REFRESH_MS};
pub use error::ErrCode;
pub use reply::Binding;
pub use session::{
    CloseReason, Session, SessionLimits, SessionState, LOST_LINES_PER_S, PROTOCOL_VERSION,
};
