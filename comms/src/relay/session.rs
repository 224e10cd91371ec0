//! One relay client's session as a sans-IO state machine: bytes in, bytes out, a deadline.
//!
//! The driver feeds what the client sent with [`Session::handle_input`], tells it about
//! blackboard changes and talk messages, calls [`Session::handle_timeout`] at
//! [`Session::poll_timeout`], and writes [`Session::pending_output`] to the socket,
//! reporting progress with [`Session::consume_output`]. After every input, drain the
//! output and check [`Session::state`].
//!
//! Memory per session is bounded: a partial line is kept up to
//! [`SessionLimits::max_line_bytes`] (a longer line is answered with `ERR 402` and
//! discarded up to its end), and unsent output up to [`SessionLimits::max_output_bytes`];
//! a client that lets more pile up (it stopped reading, or floods commands without
//! reading the answers) is cut off: its state becomes [`SessionState::Closed`] with
//! [`CloseReason::OutputOverflow`] and its buffers are freed.

use std::collections::BTreeSet;
use std::io::Write as _;
use std::time::Duration;

use crate::blackboard::Entry;
use crate::key::{Key, Kind, Scope};
use crate::pattern::Pattern;
use crate::time::Instant;
use crate::value::Value;

use super::board::Board;
use super::command::{Command, Rejected};
use super::error::ErrCode;

/// The relay protocol version in the greeting. 2: `VAL`/`UPD` lines may end in flag words
/// (`departed`), `LOST` lines, `GETV key max_age_ms`.
pub const PROTOCOL_VERSION: u32 = 2;

/// Per-session memory and watch limits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SessionLimits {
    /// Longest accepted line in bytes, without its terminator (default 4096).
    pub max_line_bytes: usize,
    /// Most unsent output bytes before the client is cut off (default 1 MiB).
    pub max_output_bytes: usize,
    /// Most watch patterns per session (default 256).
    pub max_watches: usize,
}

impl Default for SessionLimits {
    fn default() -> SessionLimits {
        SessionLimits {
            max_line_bytes: 4096,
            max_output_bytes: 1 << 20,
            max_watches: 256,
        }
    }
}

/// Why a session ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CloseReason {
    /// The client sent `QUIT` (and `BYE` was sent).
    Quit,
    /// More than `max_output_bytes` were waiting to be sent: the client does not read.
    OutputOverflow,
}

/// Where a session is in its life.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SessionState {
    /// Taking commands.
    Open,
    /// `QUIT` received: send the rest of the output (ending in `BYE`), then close.
    Closing,
    /// Close the connection now; any output left is to be dropped.
    Closed(CloseReason),
}

/// How watched values are pushed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Refresh {
    /// No pushes (until `REFR`).
    Off,
    /// Every watched binding each period.
    Every { period: Duration, next: Instant },
    /// Each change as it happens (`REFR 0`).
    OnChange,
}

/// One client's session. See the module docs for the run loop.
#[derive(Debug)]
pub struct Session {
    limits: SessionLimits,
    /// The current line so far (never longer than `max_line_bytes`).
    line: Vec<u8>,
    /// Inside an over-long line: skip to its end.
    discarding: bool,
    output: Vec<u8>,
    /// Bytes of `output` already written.
    sent: usize,
    watches: Vec<Pattern>,
    refresh: Refresh,
    state: SessionState,
    /// `LOST` lines still allowed (a bucket refilled at [`LOST_LINES_PER_S`]), and when it
    /// was last refilled.
    lost_allowance: (f64, Option<Instant>),
    /// `LOST` lines not sent because the allowance was spent.
    lost_suppressed: u64,
    /// Patterns and keys refused because they are not ASCII.
    non_ascii_refused: u64,
}

/// `LOST` lines a session sends per second at most (a burst of as many): given-up talk
/// is the sender's word, and unkeyed talk heads can make a relay give up messages as fast
/// as an attacker sends them. Those beyond are counted ([`Session::lost_suppressed`]);
/// the client still sees the gap in the sequence numbers of the `UPD` lines.
pub const LOST_LINES_PER_S: f64 = 20.0;

impl Session {
    /// A new session for robot `robot_id`; the greeting `HUDDLE <version> robot <id>` is
    /// the first output.
    pub fn new(robot_id: u8, limits: SessionLimits) -> Session {
        let mut s = Session {
            limits,
            line: Vec::new(),
            discarding: false,
            output: Vec::new(),
            sent: 0,
            watches: Vec::new(),
            refresh: Refresh::Off,
            state: SessionState::Open,
            lost_allowance: (LOST_LINES_PER_S, None),
            lost_suppressed: 0,
            non_ascii_refused: 0,
        };
        s.push(format_args!("HUDDLE {PROTOCOL_VERSION} robot {robot_id}"));
        s
    }

    /// The session's state; check it after every input.
    pub fn state(&self) -> SessionState {
        self.state
    }

    /// Whether the connection should be closed now: cut off, or quit with all output
    /// sent.
    pub fn is_finished(&self) -> bool {
        match self.state {
            SessionState::Open => false,
            SessionState::Closing => self.pending_output().is_empty(),
            SessionState::Closed(_) => true,
        }
    }

    /// The watch patterns, in the order they were added.
    pub fn watches(&self) -> &[Pattern] {
        &self.watches
    }

    /// Whether changes are pushed as they happen (`REFR 0`): only then does
    /// [`Session::handle_change`] do anything.
    pub fn wants_changes(&self) -> bool {
        self.refresh == Refresh::OnChange && !self.watches.is_empty()
    }

    /// Bytes waiting to be written to the client.
    pub fn pending_output(&self) -> &[u8] {
        &self.output[self.sent..]
    }

    /// Marks the first `n` bytes of [`Session::pending_output`] as written.
    pub fn consume_output(&mut self, n: usize) {
        self.sent = (self.sent + n).min(self.output.len());
        if self.sent == self.output.len() {
            self.output.clear();
            self.sent = 0;
        } else if self.sent >= 64 * 1024 && self.sent * 2 >= self.output.len() {
            // Compact now and then so the buffer does not creep forward forever.
            self.output.drain(..self.sent);
            self.sent = 0;
        }
    }

    /// When [`Session::handle_timeout`] should next be called (periodic `REFR` only).
    pub fn poll_timeout(&self) -> Option<Instant> {
        match (self.state, self.refresh) {
            (SessionState::Open, Refresh::Every { next, .. }) if !self.watches.is_empty() => {
                Some(next)
            }
            _ => None,
        }
    }

    /// Feeds bytes the client sent: every complete line is executed against `board`.
    pub fn handle_input<B: Board + ?Sized>(&mut self, now: Instant, bytes: &[u8], board: &mut B) {
        let mut rest = bytes;
        while self.state == SessionState::Open && !rest.is_empty() {
            let newline = rest.iter().position(|&b| b == b'\n');
            let (chunk, after) = match newline {
                Some(i) => (&rest[..i], Some(&rest[i + 1..])),
                None => (rest, None),
            };
            if !self.discarding {
                if self.line.len() + chunk.len() > self.limits.max_line_bytes + 1 {
                    // +1: room for the '\r' of a "\r\n" terminator.
                    self.line.clear();
                    self.line.shrink_to(self.limits.max_line_bytes + 1);
                    self.discarding = true;
                    let limit = self.limits.max_line_bytes;
                    self.push_err(&Rejected::new(
                        ErrCode::LineTooLong,
                        format!("line longer than {limit} bytes: discarded"),
                    ));
                } else {
                    self.line.extend_from_slice(chunk);
                }
            }
            match after {
                Some(after) => {
                    if self.discarding {
                        self.discarding = false;
                    } else {
                        let mut line = std::mem::take(&mut self.line);
                        if line.last() == Some(&b'\r') {
                            line.pop();
                        }
                        if line.len() > self.limits.max_line_bytes {
                            let limit = self.limits.max_line_bytes;
                            self.push_err(&Rejected::new(
                                ErrCode::LineTooLong,
                                format!("line longer than {limit} bytes: discarded"),
                            ));
                        } else {
                            self.execute_line(now, &line, board);
                        }
                        line.clear();
                        self.line = line;
                    }
                    rest = after;
                }
                None => rest = &[],
            }
        }
    }

    fn execute_line<B: Board + ?Sized>(&mut self, now: Instant, line: &[u8], board: &mut B) {
        let Ok(text) = std::str::from_utf8(line) else {
            return self.push_err(&Rejected::new(ErrCode::NotText, "line is not UTF-8 text"));
        };
        if text.trim().is_empty() {
            return; // a bare Enter from a person at a terminal
        }
        match Command::parse(text) {
            // Keys are ASCII (`[A-Za-z0-9_-]` and the scope), so a pattern with anything
            // else would be accepted and never match: refused, as a bad key is.
            Ok(Command::AddWatch(ref p) | Command::DelWatch(ref p)) if !p.as_str().is_ascii() => {
                self.non_ascii_refused += 1;
                let text = format!(
                    "pattern {:?} is not ASCII: keys are ASCII, so it would never match",
                    p.as_str()
                );
                self.push_err(&Rejected::new(ErrCode::BadPattern, text));
            }
            Ok(command) => self.execute(now, command, board),
            Err(rejected) => {
                let key = text.split_whitespace().nth(1).unwrap_or("");
                if rejected.code == ErrCode::BadKey && !key.is_ascii() {
                    self.non_ascii_refused += 1;
                }
                self.push_err(&rejected)
            }
        }
    }

    fn execute<B: Board + ?Sized>(&mut self, now: Instant, command: Command, board: &mut B) {
        match command {
            Command::Get(key, max_age_ms) => {
                if key.kind() == Kind::Talk {
                    return self.push_err(&Rejected::new(
                        ErrCode::WrongKind,
                        format!("{key} is a talk queue: it has no value (watch it instead)"),
                    ));
                }
                match board.get(&key) {
                    Some(entry) => {
                        let stored = stored_key(&key, entry);
                        let age_ms = entry.age(now).as_millis();
                        match max_age_ms {
                            Some(max) if age_ms > u128::from(max) => self.push_err(&Rejected::new(
                                ErrCode::TooOld,
                                format!("{stored} is {age_ms} ms old, more than {max} ms"),
                            )),
                            _ => self.push_binding("VAL", &stored, entry, now, board),
                        }
                    }
                    None => self.push_err(&Rejected::new(
                        ErrCode::NotFound,
                        format!("no value for {key}"),
                    )),
                }
            }
            Command::Set(key, value) => {
                let result = match key.kind() {
                    Kind::Var => board.set(now, &key, value),
                    Kind::Talk => board.post(now, &key, value),
                };
                match result {
                    Ok(()) => self.push(format_args!("OK")),
                    Err(rejected) => self.push_err(&rejected),
                }
            }
            Command::SetPriority(key, value) => {
                let result = match key.kind() {
                    Kind::Var => board.set_priority(now, &key, value),
                    Kind::Talk => board.post(now, &key, value),
                };
                match result {
                    Ok(()) => self.push(format_args!("OK")),
                    Err(rejected) => self.push_err(&rejected),
                }
            }
            Command::GameClock(secs) => {
                match board.set_game_clock(now, std::time::Duration::from_secs_f64(secs)) {
                    Ok(()) => self.push(format_args!("OK")),
                    Err(rejected) => self.push_err(&rejected),
                }
            }
            Command::AddWatch(pattern) => {
                if self.watches.contains(&pattern) {
                    return self.push(format_args!("OK"));
                }
                if self.watches.len() >= self.limits.max_watches {
                    let max = self.limits.max_watches;
                    return self.push_err(&Rejected::new(
                        ErrCode::TooMany,
                        format!("at most {max} watch patterns"),
                    ));
                }
                self.watches.push(pattern);
                self.push(format_args!("OK"));
                if self.refresh == Refresh::OnChange {
                    // A new watch in push mode starts with what it matches now.
                    let pattern = self.watches.last().cloned();
                    if let Some(pattern) = pattern {
                        self.push_snapshot(now, std::slice::from_ref(&pattern), board);
                    }
                }
            }
            Command::DelWatch(pattern) => match self.watches.iter().position(|w| *w == pattern) {
                Some(i) => {
                    self.watches.remove(i);
                    self.push(format_args!("OK"));
                }
                None => self.push_err(&Rejected::new(
                    ErrCode::NotFound,
                    format!("{pattern} is not watched"),
                )),
            },
            Command::ClearWatches => {
                self.watches.clear();
                self.push(format_args!("OK"));
            }
            Command::ListWatches => {
                for i in 0..self.watches.len() {
                    let text = self.watches[i].as_str().to_owned();
                    self.push(format_args!("WATCH {text}"));
                }
                self.push(format_args!("END"));
            }
            Command::Refresh(ms) => {
                self.refresh = if ms == 0 {
                    Refresh::OnChange
                } else {
                    let period = Duration::from_millis(ms);
                    Refresh::Every {
                        period,
                        next: now + period,
                    }
                };
                self.push(format_args!("OK"));
                // Either way the client starts from the current state of what it watches.
                let watches = std::mem::take(&mut self.watches);
                self.push_snapshot(now, &watches, board);
                self.watches = watches;
            }
            Command::Quit => {
                self.push(format_args!("BYE"));
                if self.state == SessionState::Open {
                    self.state = SessionState::Closing;
                }
            }
        }
    }

    /// Runs the periodic `REFR` push if it is due.
    pub fn handle_timeout<B: Board + ?Sized>(&mut self, now: Instant, board: &B) {
        if self.state != SessionState::Open {
            return;
        }
        let Refresh::Every { period, next } = self.refresh else {
            return;
        };
        if now < next {
            return;
        }
        // Skip missed periods instead of bursting to catch up.
        let mut next = next + period;
        if next <= now {
            next = now + period;
        }
        self.refresh = Refresh::Every { period, next };
        let watches = std::mem::take(&mut self.watches);
        self.push_snapshot(now, &watches, board);
        self.watches = watches;
    }

    /// A stored binding changed (`key` as stored: `local.var.x` or `n.var.x`): with
    /// `REFR 0` and a matching watch, push it.
    pub fn handle_change<B: Board + ?Sized>(&mut self, now: Instant, key: &Key, board: &B) {
        if self.state != SessionState::Open || !self.wants_changes() {
            return;
        }
        if !self.watches.iter().any(|w| w.matches(key)) {
            return;
        }
        if let Some(entry) = board.get(key) {
            self.push_binding("UPD", key, entry, now, board);
        }
    }

    /// A teammate's talk message was delivered: pushed at once, whatever `REFR` says,
    /// as `UPD <from>.talk.<queue> type value 0` if a watch matches.
    pub fn handle_talk(&mut self, from: u8, queue: &str, value: &Value) {
        if self.watches_talk(from, queue) {
            let ty = value.value_type();
            self.push(format_args!("UPD {from}.talk.{queue} {ty} {value} 0"));
        }
    }

    /// Messages `first..=last` of a teammate's talk queue were given up (they can no
    /// longer arrive): pushed at once, whatever `REFR` says, as
    /// `LOST <from>.talk.<queue> <first> <last>` if a watch matches.
    ///
    /// At most [`LOST_LINES_PER_S`] a second (with a burst of as many); the rest are
    /// counted in [`Session::lost_suppressed`].
    pub fn handle_talk_lost(&mut self, now: Instant, from: u8, queue: &str, first: u64, last: u64) {
        if !self.watches_talk(from, queue) {
            return;
        }
        let (mut allowance, at) = self.lost_allowance;
        if let Some(at) = at {
            let dt = now.saturating_duration_since(at).as_secs_f64();
            allowance = (allowance + dt * LOST_LINES_PER_S).min(LOST_LINES_PER_S);
        }
        if allowance < 1.0 {
            self.lost_allowance = (allowance, Some(now));
            self.lost_suppressed += 1;
            return;
        }
        self.lost_allowance = (allowance - 1.0, Some(now));
        self.push(format_args!("LOST {from}.talk.{queue} {first} {last}"));
    }

    /// `LOST` lines not sent because this client's allowance was spent.
    pub fn lost_suppressed(&self) -> u64 {
        self.lost_suppressed
    }

    /// Watch patterns (`ERR 411`) and keys (`ERR 410`) this client sent that were refused
    /// for not being ASCII.
    pub fn non_ascii_refused(&self) -> u64 {
        self.non_ascii_refused
    }

    /// Whether the session is open and watches `from`'s talk queue `queue`.
    fn watches_talk(&self, from: u8, queue: &str) -> bool {
        self.state == SessionState::Open
            && self
                .watches
                .iter()
                .any(|w| w.matches_parts(Scope::Robot(from), Kind::Talk, queue))
    }

    fn push_snapshot<B: Board + ?Sized>(&mut self, now: Instant, watches: &[Pattern], board: &B) {
        match watches {
            [] => {}
            [one] => board.visit(one, &mut |key, entry| {
                self.push_binding("UPD", key, entry, now, board)
            }),
            many => {
                // Overlapping patterns: each binding once, in key order.
                let mut keys = BTreeSet::new();
                for w in many {
                    board.visit(w, &mut |key, _| {
                        keys.insert(key.clone());
                    });
                }
                for key in keys {
                    if let Some(entry) = board.get(&key) {
                        self.push_binding("UPD", &key, entry, now, board);
                    }
                }
            }
        }
    }

    fn push_binding<B: Board + ?Sized>(
        &mut self,
        word: &str,
        key: &Key,
        entry: &Entry,
        now: Instant,
        board: &B,
    ) {
        let age_ms = entry.age(now).as_millis();
        let ty = entry.value.value_type();
        let departed = match key.scope() {
            Scope::Robot(owner) if board.departed(owner) => " departed",
            _ => "",
        };
        self.push(format_args!(
            "{word} {key} {ty} {} {age_ms}{departed}",
            entry.value
        ));
    }

    fn push_err(&mut self, rejected: &Rejected) {
        // The text is one line whatever it quotes.
        let text = rejected.text.replace(['\r', '\n'], " ");
        self.push(format_args!("ERR {} {text}", rejected.code));
    }

    fn push(&mut self, line: std::fmt::Arguments<'_>) {
        if matches!(self.state, SessionState::Closed(_)) {
            return;
        }
        // Writing into a Vec cannot fail.
        let _ = self.output.write_fmt(line);
        self.output.push(b'\n');
        if self.output.len() - self.sent > self.limits.max_output_bytes {
            self.state = SessionState::Closed(CloseReason::OutputOverflow);
            self.output = Vec::new();
            self.sent = 0;
            self.line = Vec::new();
            self.watches.clear();
        }
    }
}

/// The key a reply names: for `*.var.x` the copy that answered (`n.var.x`).
fn stored_key(asked: &Key, entry: &Entry) -> Key {
    match asked.scope() {
        Scope::Global => asked.with_scope(Scope::Robot(entry.owner)),
        _ => asked.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blackboard::Blackboard;

    fn t(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    /// Robot 2's session over a bare blackboard, greeting already read.
    fn open() -> (Session, Blackboard) {
        let mut s = Session::new(2, SessionLimits::default());
        assert_eq!(take(&mut s), "HUDDLE 2 robot 2\n");
        (s, Blackboard::new(2))
    }

    fn take(s: &mut Session) -> String {
        let out = String::from_utf8(s.pending_output().to_vec()).unwrap();
        let n = s.pending_output().len();
        s.consume_output(n);
        out
    }

    fn say(s: &mut Session, bb: &mut Blackboard, now: Instant, bytes: &str) -> String {
        s.handle_input(now, bytes.as_bytes(), bb);
        take(s)
    }

    #[test]
    fn every_command_answers_in_the_documented_grammar() {
        let (mut s, mut bb) = open();
        assert_eq!(
            say(&mut s, &mut bb, t(0), "SETV *.var.ball.dist 1.5\n"),
            "OK\n"
        );
        assert_eq!(
            say(
                &mut s,
                &mut bb,
                t(0),
                "setv local.var.name \"say \\\"hi\\\"\"\r\n"
            ),
            "OK\n",
            "lower-case words and CRLF are accepted"
        );
        assert_eq!(
            say(&mut s, &mut bb, t(250), "GETV *.var.ball.dist\n"),
            "VAL 2.var.ball.dist float 1.5 250\n",
            "the reply names the copy that answered and its age"
        );
        assert_eq!(
            say(&mut s, &mut bb, t(250), "GETV local.var.name\n"),
            "VAL local.var.name string \"say \\\"hi\\\"\" 250\n"
        );
        assert_eq!(say(&mut s, &mut bb, t(0), "ADDW 2.var.#\n"), "OK\n");
        assert_eq!(say(&mut s, &mut bb, t(0), "ADDW local.var.+\n"), "OK\n");
        assert_eq!(
            say(&mut s, &mut bb, t(0), "LSTW\n"),
            "WATCH 2.var.#\nWATCH local.var.+\nEND\n"
        );
        assert_eq!(say(&mut s, &mut bb, t(0), "DELW 2.var.#\n"), "OK\n");
        assert_eq!(
            say(&mut s, &mut bb, t(0), "LSTW\n"),
            "WATCH local.var.+\nEND\n"
        );
        assert_eq!(say(&mut s, &mut bb, t(0), "CLRW\n"), "OK\n");
        assert_eq!(say(&mut s, &mut bb, t(0), "LSTW\n"), "END\n");
        assert_eq!(
            say(&mut s, &mut bb, t(0), "\n\r\n"),
            "",
            "empty lines are ignored"
        );
        assert_eq!(
            say(&mut s, &mut bb, t(0), "QUIT\nGETV local.var.name\n"),
            "BYE\n"
        );
        assert_eq!(s.state(), SessionState::Closing);
        assert!(s.is_finished(), "all output sent after BYE: close");
    }

    #[test]
    fn setp_spends_the_budget_reserve_at_once_where_setv_waits_for_the_pacing() {
        // Robot 2 of a five-robot SPL team has spent what its pacing allows: the next
        // frame is seconds away. A SETV waits for it; a SETP (a goer change) goes now.
        use crate::{BudgetSpec, Replica, ReplicaConfig};
        let spec: BudgetSpec = "spl".parse().expect("a league");
        let cfg = ReplicaConfig::new(2, 7).with_budget(&spec, 5);
        let mut r = Replica::new(cfg, 1, t(0)).expect("a valid config");
        while r.poll_transmit().is_some() {}
        let mut s = Session::new(2, SessionLimits::default());
        s.consume_output(s.pending_output().len());
        let mut say = |line: &str, r: &mut Replica| {
            s.handle_input(t(10), line.as_bytes(), r);
            let out = String::from_utf8(s.pending_output().to_vec()).unwrap();
            s.consume_output(out.len());
            out
        };
        // Spend what the pacing allows now: then it holds a plain value.
        let mut held = false;
        for i in 0..200 {
            assert_eq!(say(&format!("SETV *.var.mode {i}\n"), &mut r), "OK\n");
            if r.poll_transmit().is_none() {
                held = true;
                break;
            }
            while r.poll_transmit().is_some() {}
        }
        assert!(
            held,
            "an SPL share's pacing holds a frame within 200 writes"
        );
        assert_eq!(
            say("SETP *.var.machine.heuristic [1.5, 1]\n", &mut r),
            "OK\n"
        );
        assert!(
            r.poll_transmit().is_some(),
            "a priority item goes at once, from the reserve"
        );
        assert_eq!(say("CLOK 600\n", &mut r), "OK\n");
        assert!(say("CLOK -1\n", &mut r).starts_with("ERR 412 "));
        assert!(say("CLOK soon\n", &mut r).starts_with("ERR 412 "));
        assert!(say("SETP *.var.x\n", &mut r).starts_with("ERR 401 usage: SETP"));
    }

    #[test]
    fn every_error_has_its_code_and_the_session_carries_on() {
        let (mut s, mut bb) = open();
        bb.apply_remote(3, 7, "x".into(), Value::Int(1), 1, t(0));
        let cases = [
            ("HELLO\n", "ERR 400 "),
            ("GETV\n", "ERR 401 "),
            ("GETV a b\n", "ERR 401 "),
            ("SETV *.var.x\n", "ERR 401 "),
            ("CLRW now\n", "ERR 401 "),
            ("GETV local.var.none\n", "ERR 404 "),
            ("DELW 1.var.x\n", "ERR 404 "),
            ("GETV 0.var.x\n", "ERR 410 "),
            ("SETV *.var.a..b 1\n", "ERR 410 "),
            ("ADDW 2.var.#.x\n", "ERR 411 "),
            ("SETV *.var.x hello\n", "ERR 412 "),
            ("SETV *.var.x \"open\n", "ERR 412 "),
            ("REFR -5\n", "ERR 413 "),
            ("REFR 3600001\n", "ERR 413 "),
            ("SETV 3.var.x 2\n", "ERR 420 "),
            ("GETV *.talk.plan\n", "ERR 421 "),
            ("SETV *.talk.plan 1\n", "ERR 503 "),
        ];
        for (line, want) in cases {
            let got = say(&mut s, &mut bb, t(0), line);
            assert!(
                got.starts_with(want) && got.ends_with('\n') && got.matches('\n').count() == 1,
                "{line:?} answered {got:?}, expected one line starting {want:?}"
            );
        }
        s.handle_input(t(0), b"GETV \xff\xfe\n", &mut bb);
        assert!(take(&mut s).starts_with("ERR 403 "));
        assert_eq!(
            say(&mut s, &mut bb, t(0), "GETV 3.var.x\n"),
            "VAL 3.var.x int 1 0\n",
            "after every error the session still works"
        );
        assert_eq!(
            bb.get(&Key::parse("3.var.x").unwrap()).unwrap().value,
            Value::Int(1)
        );
    }

    #[test]
    fn a_non_ascii_pattern_or_key_is_refused_and_counted() {
        // Robot 1's relay; a client types a pattern and keys with an accented letter, a
        // Greek letter and a non-breaking hyphen. Keys are ASCII: the pattern would never
        // match, so it is refused like a malformed one.
        let (mut s, mut bb) = open();
        let cases = [
            (
                "ADDW *.var.bal\u{e9}.#\n",
                "ERR 411 pattern \"*.var.bal\u{e9}.#\" is not ASCII",
            ),
            ("ADDW +.var.\u{3b2}\n", "ERR 411 "),
            ("DELW 2.var.x\u{2011}y\n", "ERR 411 "),
            ("addw \u{1f916}.var.#\n", "ERR 411 "),
            ("SETV *.var.caf\u{e9} 1\n", "ERR 410 "),
            ("GETV 3.var.\u{3b2}\n", "ERR 410 "),
            ("SETV *.talk.pl\u{e4}n 1\n", "ERR 410 "),
            ("SETP local.var.\u{e9} 1\n", "ERR 410 "),
        ];
        for (i, (line, want)) in cases.iter().enumerate() {
            let got = say(&mut s, &mut bb, t(0), line);
            assert!(
                got.starts_with(want),
                "{line:?} answered {got:?}, expected {want:?}"
            );
            assert_eq!(s.non_ascii_refused(), i as u64 + 1, "{line:?} is counted");
        }
        assert_eq!(
            say(&mut s, &mut bb, t(0), "LSTW\n"),
            "END\n",
            "no watch was added"
        );
        // Non-ASCII inside a string value is text, not a key: accepted, not counted.
        assert_eq!(
            say(&mut s, &mut bb, t(0), "SETV local.var.name \"Jos\u{e9}\"\n"),
            "OK\n"
        );
        assert_eq!(
            say(&mut s, &mut bb, t(0), "ADDW 2.var.x!y\n"),
            "OK\n",
            "ASCII: as before"
        );
        assert_eq!(s.non_ascii_refused(), cases.len() as u64);
    }

    #[test]
    fn too_many_watches_is_refused() {
        let limits = SessionLimits {
            max_watches: 2,
            ..SessionLimits::default()
        };
        let mut s = Session::new(1, limits);
        let mut bb = Blackboard::new(1);
        take(&mut s);
        assert_eq!(
            say(&mut s, &mut bb, t(0), "ADDW a.b\nADDW a.c\nADDW a.b\n"),
            "OK\nOK\nOK\n"
        );
        assert!(say(&mut s, &mut bb, t(0), "ADDW a.d\n").starts_with("ERR 429 "));
    }

    #[test]
    fn a_one_mebibyte_line_gets_one_error_and_bounded_memory() {
        let (mut s, mut bb) = open();
        let mut huge = b"SETV local.var.x \"".to_vec();
        huge.extend(std::iter::repeat_n(b'a', 1 << 20));
        huge.extend_from_slice(b"\"\nGETV local.var.x\nSETV local.var.y 5\n");
        // Fed in 8 KiB pieces, as a socket would deliver it.
        let mut out = String::new();
        for piece in huge.chunks(8192) {
            s.handle_input(t(0), piece, &mut bb);
            assert!(
                s.line.capacity() <= 2 * 4097,
                "the partial line stays bounded"
            );
            out += &take(&mut s);
        }
        let lines: Vec<&str> = out.lines().collect();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert!(lines[0].starts_with("ERR 402 "), "{lines:?}");
        assert!(
            lines[1].starts_with("ERR 404 "),
            "the huge SETV was not executed"
        );
        assert_eq!(lines[2], "OK");
    }

    #[test]
    fn a_line_of_exactly_the_limit_is_accepted_and_one_byte_more_is_not() {
        let (mut s, mut bb) = open();
        let prefix = "SETV local.var.s \"";
        let body = "b".repeat(4096 - prefix.len() - 1);
        let line = format!("{prefix}{body}\"");
        assert_eq!(line.len(), 4096);
        assert_eq!(say(&mut s, &mut bb, t(0), &format!("{line}\r\n")), "OK\n");
        let longer = format!("{prefix}{body}b\"");
        assert!(say(&mut s, &mut bb, t(0), &format!("{longer}\n")).starts_with("ERR 402 "));
    }

    #[test]
    fn commands_split_across_reads_byte_by_byte_work() {
        let (mut s, mut bb) = open();
        for b in b"SETV *.var.n 42\nGETV *.var.n\n" {
            s.handle_input(t(5), std::slice::from_ref(b), &mut bb);
        }
        assert_eq!(take(&mut s), "OK\nVAL 2.var.n int 42 0\n");
    }

    #[test]
    fn periodic_refresh_pushes_every_watched_binding_each_period() {
        let (mut s, mut bb) = open();
        say(
            &mut s,
            &mut bb,
            t(0),
            "SETV *.var.a 1\nSETV local.var.b true\n",
        );
        bb.apply_remote(4, 9, "a".into(), Value::Int(7), 1, t(0));
        assert_eq!(s.poll_timeout(), None, "no timer before REFR");
        // Two overlapping patterns: each binding pushed once, in key order.
        assert_eq!(
            say(
                &mut s,
                &mut bb,
                t(0),
                "ADDW +.var.a\nADDW 4.var.#\nREFR 100\n"
            ),
            "OK\nOK\nOK\nUPD 2.var.a int 1 0\nUPD 4.var.a int 7 0\n"
        );
        assert_eq!(s.poll_timeout(), Some(t(100)));
        s.handle_timeout(t(99), &bb);
        assert_eq!(take(&mut s), "", "not due yet");
        s.handle_timeout(t(100), &bb);
        assert_eq!(
            take(&mut s),
            "UPD 2.var.a int 1 100\nUPD 4.var.a int 7 100\n"
        );
        assert_eq!(s.poll_timeout(), Some(t(200)));
        // A stall of several periods gives one push, not a burst.
        s.handle_timeout(t(450), &bb);
        assert_eq!(take(&mut s).lines().count(), 2);
        assert_eq!(s.poll_timeout(), Some(t(550)));
    }

    #[test]
    fn refr_zero_pushes_each_matching_change_as_it_happens() {
        let (mut s, mut bb) = open();
        say(&mut s, &mut bb, t(0), "SETV *.var.pose 1.0\n");
        while bb.poll_change().is_some() {} // before the watch: not this session's business
        assert_eq!(
            say(&mut s, &mut bb, t(0), "ADDW +.var.pose\nREFR 0\n"),
            "OK\nOK\nUPD 2.var.pose float 1.0 0\n"
        );
        assert_eq!(s.poll_timeout(), None);
        bb.apply_remote(3, 1, "pose".into(), Value::Float(2.0), 1, t(10));
        bb.apply_remote(3, 1, "other".into(), Value::Int(0), 1, t(10));
        while let Some(key) = bb.poll_change() {
            s.handle_change(t(15), &key, &bb);
        }
        assert_eq!(take(&mut s), "UPD 3.var.pose float 2.0 5\n");
        say(&mut s, &mut bb, t(20), "SETV local.var.pose 0\n");
        assert_eq!(
            say(&mut s, &mut bb, t(20), "ADDW local.var.#\n"),
            "OK\nUPD local.var.pose int 0 0\n",
            "a new watch in push mode starts from the current state"
        );
        s.handle_talk(3, "plan", &Value::String("go".into()));
        assert_eq!(take(&mut s), "", "talk messages need a matching watch");
        say(&mut s, &mut bb, t(20), "ADDW +.talk.plan\n");
        s.handle_talk(3, "plan", &Value::String("go".into()));
        assert_eq!(take(&mut s), "UPD 3.talk.plan string \"go\" 0\n");
    }

    #[test]
    fn a_client_that_never_reads_is_cut_off_with_its_memory_freed() {
        let mut s = Session::new(1, SessionLimits::default());
        let mut bb = Blackboard::new(1);
        s.handle_input(t(0), b"ADDW local.var.#\nREFR 0\n", &mut bb);
        let key = Key::parse("local.var.counter").unwrap();
        let mut i = 0;
        while s.state() == SessionState::Open {
            i += 1;
            assert!(i < 1_000_000, "never cut off");
            bb.set(t(i), &key, Value::Int(i as i64)).unwrap();
            while let Some(k) = bb.poll_change() {
                s.handle_change(t(i), &k, &bb);
            }
            assert!(s.pending_output().len() <= (1 << 20) + 100);
        }
        assert_eq!(s.state(), SessionState::Closed(CloseReason::OutputOverflow));
        assert!(s.is_finished());
        assert_eq!(s.pending_output().len(), 0);
        assert_eq!(s.output.capacity(), 0, "the buffer is freed");
        // Further input is ignored.
        s.handle_input(t(0), b"GETV local.var.counter\n", &mut bb);
        assert_eq!(s.pending_output().len(), 0);
    }

    #[test]
    fn a_flood_of_commands_without_reading_is_cut_off() {
        let mut s = Session::new(1, SessionLimits::default());
        let mut bb = Blackboard::new(1);
        let flood = "LSTW\n".repeat(1000);
        let mut rounds = 0;
        while s.state() == SessionState::Open {
            rounds += 1;
            assert!(rounds < 10_000, "never cut off");
            s.handle_input(t(0), flood.as_bytes(), &mut bb);
        }
        assert_eq!(s.state(), SessionState::Closed(CloseReason::OutputOverflow));
    }

    #[test]
    fn getv_with_a_maximum_age_refuses_an_older_value_with_its_own_code() {
        let (mut s, mut bb) = open();
        say(&mut s, &mut bb, t(0), "SETV *.var.pose 1.0\n");
        assert_eq!(
            say(&mut s, &mut bb, t(500), "GETV *.var.pose 500\n"),
            "VAL 2.var.pose float 1.0 500\n"
        );
        let refused = say(&mut s, &mut bb, t(501), "GETV *.var.pose 500\n");
        assert!(
            refused.starts_with("ERR 406 2.var.pose is 501 ms old"),
            "{refused}"
        );
        assert!(say(&mut s, &mut bb, t(501), "GETV *.var.none 500\n").starts_with("ERR 404 "));
        for bad in [
            "GETV *.var.pose -1\n",
            "GETV *.var.pose soon\n",
            "GETV *.var.pose 1 2\n",
        ] {
            assert!(
                say(&mut s, &mut bb, t(501), bad).starts_with("ERR 401 "),
                "{bad}"
            );
        }
        assert_eq!(
            say(&mut s, &mut bb, t(501), "GETV *.var.pose\n"),
            "VAL 2.var.pose float 1.0 501\n",
            "without a maximum, any age"
        );
    }

    #[test]
    fn given_up_talk_messages_reach_watching_clients_as_lost_lines() {
        let (mut s, mut bb) = open();
        s.handle_talk_lost(t(0), 3, "plan", 4, 7);
        assert_eq!(take(&mut s), "", "nobody watches the queue");
        say(&mut s, &mut bb, t(0), "ADDW +.talk.plan\n");
        s.handle_talk(3, "plan", &Value::Int(3));
        s.handle_talk_lost(t(0), 3, "plan", 4, 7);
        s.handle_talk_lost(t(0), 3, "other", 1, 1);
        s.handle_talk(3, "plan", &Value::Int(8));
        assert_eq!(
            take(&mut s),
            "UPD 3.talk.plan int 3 0\nLOST 3.talk.plan 4 7\nUPD 3.talk.plan int 8 0\n"
        );
    }

    /// Unkeyed talk heads can make the relay give up messages as fast as an attacker
    /// sends them: a watching client gets at most `LOST_LINES_PER_S` lines a second
    /// (it got one per give-up, 2.5x the attacker's bytes), and the rest are counted.
    #[test]
    fn lost_lines_are_rate_limited_per_client_and_counted() {
        let (mut s, mut bb) = open();
        say(&mut s, &mut bb, t(0), "ADDW +.talk.#\n");
        take(&mut s);
        // 1,000 give-ups a second for 10 s.
        for ms in 0..10_000u64 {
            s.handle_talk_lost(t(ms), 9, "q", ms + 1, ms + 1);
        }
        let lines = take(&mut s)
            .lines()
            .filter(|l| l.starts_with("LOST "))
            .count();
        let most = (LOST_LINES_PER_S * 11.0) as usize;
        assert!(lines <= most, "{lines} LOST lines in 10 s (at most {most})");
        assert!(lines >= 100, "the limit still lets {lines} through");
        assert_eq!(s.lost_suppressed() as usize, 10_000 - lines);
    }

    #[test]
    fn new_local_keys_beyond_the_limit_get_an_error_and_old_ones_still_change() {
        let limits = crate::BoardLimits {
            local: 2,
            ..crate::BoardLimits::default()
        };
        let mut bb = Blackboard::with_limits(2, limits);
        let mut s = Session::new(2, SessionLimits::default());
        take(&mut s);
        assert_eq!(
            say(
                &mut s,
                &mut bb,
                t(0),
                "SETV local.var.a 1\nSETV local.var.b 1\n"
            ),
            "OK\nOK\n"
        );
        let refused = say(&mut s, &mut bb, t(0), "SETV local.var.c 1\n");
        assert!(
            refused.starts_with("ERR 429 local.var.c: no room"),
            "{refused}"
        );
        assert_eq!(say(&mut s, &mut bb, t(0), "SETV local.var.a 2\n"), "OK\n");
        assert_eq!(bb.len(), 2);
    }

    #[test]
    fn a_departed_robots_values_are_flagged_until_released() {
        use crate::{Replica, ReplicaConfig};
        let from = std::net::SocketAddr::from(([127, 0, 0, 1], 2000));
        let mut a = Replica::new(ReplicaConfig::new(1, 7), 11, t(0)).unwrap();
        let mut b = Replica::new(ReplicaConfig::new(2, 7), 22, t(0)).unwrap();
        a.set(t(0), "*.var.pose", Value::Float(1.0)).unwrap();
        while let Some(tx) = a.poll_transmit() {
            b.handle_datagram(t(1), from, &tx.payload);
        }
        let mut s = Session::new(2, SessionLimits::default());
        take(&mut s);
        s.handle_input(t(1), b"GETV 1.var.pose\nADDW 1.var.#\nREFR 1000\n", &mut b);
        assert_eq!(
            take(&mut s),
            "VAL 1.var.pose float 1.0 0\nOK\nOK\nUPD 1.var.pose float 1.0 0\n"
        );
        // Robot 1 falls silent: after departed_after it is departed.
        b.handle_timeout(t(301));
        assert!(b.is_departed(1));
        s.handle_input(t(301), b"GETV *.var.pose\n", &mut b);
        assert_eq!(take(&mut s), "VAL 1.var.pose float 1.0 300 departed\n");
        s.handle_timeout(t(1001), &b);
        let line = take(&mut s);
        assert_eq!(line, "UPD 1.var.pose float 1.0 1000 departed\n");
        let parsed = super::super::Binding::parse(line.trim_end()).unwrap();
        assert!(parsed.departed);
        // After the grace period (60 s after the departure) the values are released.
        let mut now = t(1001);
        while b.get("1.var.pose").unwrap().is_some() {
            assert!(now < t(70_000), "never released");
            now = b.poll_timeout().unwrap();
            b.handle_timeout(now);
        }
        let release = now;
        assert_eq!(
            release,
            t(1 + 300 + 60_000),
            "last heard + departure + grace"
        );
        assert_eq!(b.stats().bindings_released, 1);
        s.handle_input(release, b"GETV 1.var.pose\n", &mut b);
        assert!(take(&mut s).starts_with("ERR 404 "));
    }
}
