//! `huddle_event`: what the node and the replica report, so that nothing is lost
//! silently (talk messages, given-up talk, peers joining, departing, restarting).

use std::ffi::c_char;

use comms::{Event, Value};

use crate::text::write_text;

/// A teammate's talk message, in order, exactly once: `robot` sent message `seq` of
/// queue `name` (`plan` for `n.talk.plan`), `type` and `value` hold it.
pub const HUDDLE_EVENT_TALK_DELIVERED: i32 = 1;
/// Messages `seq..=last` of `robot`'s queue `name` could not be recovered.
pub const HUDDLE_EVENT_TALK_GIVEN_UP: i32 = 2;
/// `robot` was heard for the first time, or again after departing (`incarnation`).
pub const HUDDLE_EVENT_PEER_JOINED: i32 = 3;
/// `robot` fell silent (its values stay readable and age).
pub const HUDDLE_EVENT_PEER_DEPARTED: i32 = 4;
/// `robot` came back with a new `incarnation` (it restarted).
pub const HUDDLE_EVENT_PEER_RESTARTED: i32 = 5;
/// The node's event queue was full: `count` older events were dropped.
pub const HUDDLE_EVENT_LAGGED: i32 = 6;
/// The binding `name` (`n.var.x`, `local.var.x`) was inserted or changed. The node
/// queues it only for keys matching a pattern given to `huddle_node_watch`, with `robot`
/// the owner and `type`/`value` the new value; the replica reports every change, with
/// the name only.
pub const HUDDLE_EVENT_VALUE_CHANGED: i32 = 7;
/// Replica only: a datagram was dropped; `name` says why (e.g. `bad_tag`).
pub const HUDDLE_EVENT_FRAME_DROPPED: i32 = 8;

/// An event this version has no kind for; `name` describes it.
pub const HUDDLE_EVENT_OTHER: i32 = 9;
/// Another robot sends with this robot's id `robot` (a second node or daemon started
/// with the same id): its frames are dropped; `incarnation` is the other one's. Reported
/// at most once a second while it lasts (counted in `huddle_stats.id_conflicts`).
pub const HUDDLE_EVENT_ID_CONFLICT: i32 = 10;

/// One event. Fields an event kind does not use are zero (strings empty).
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_event {
    /// A `HUDDLE_EVENT_*` kind.
    pub kind: i32,
    /// The sender (talk) or the peer.
    pub robot: u8,
    /// The talk queue path, the changed key, or the drop reason.
    pub name: [c_char; 256],
    /// A talk message's sequence number, or the first one given up.
    pub seq: u64,
    /// The last sequence number given up.
    pub last: u64,
    /// The peer's (new) incarnation.
    pub incarnation: u64,
    /// Events dropped before this one (`HUDDLE_EVENT_LAGGED`).
    pub count: u64,
    /// A talk message's type (`int`, `string`, ...).
    pub r#type: [c_char; 16],
    /// A talk message as a literal, as in `huddle_binding`; see `value_len`.
    pub value: [c_char; 1024],
    /// Length in bytes of the whole literal; more than 1023 means `value` was cut.
    pub value_len: usize,
}

/// An event as the node queues it (the C struct is built when it is read).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum NodeEvent {
    Talk {
        from: u8,
        queue: String,
        seq: u64,
        value: Value,
    },
    TalkLost {
        from: u8,
        queue: String,
        first: u64,
        last: u64,
    },
    Joined {
        robot: u8,
        incarnation: u64,
    },
    Departed {
        robot: u8,
    },
    Restarted {
        robot: u8,
        incarnation: u64,
    },
    Lagged(u64),
    /// A watched value changed.
    Changed {
        key: String,
        owner: u8,
        value: Value,
    },
    /// Another robot sends with this robot's id.
    IdConflict {
        robot: u8,
        incarnation: u64,
    },
    /// An event with no kind of its own (`HUDDLE_EVENT_OTHER`).
    Other {
        robot: u8,
        description: String,
    },
}

fn clear(out: &mut huddle_event, kind: i32) {
    out.kind = kind;
    out.robot = 0;
    out.name[0] = 0;
    out.seq = 0;
    out.last = 0;
    out.incarnation = 0;
    out.count = 0;
    out.r#type[0] = 0;
    out.value[0] = 0;
    out.value_len = 0;
}

fn put_value(out: &mut huddle_event, value: &Value) {
    write_text(&mut out.r#type, value.value_type().name());
    let literal = value.to_string();
    write_text(&mut out.value, &literal);
    out.value_len = literal.len();
}

/// Fills `out` from a node event.
pub(crate) fn fill_node_event(out: &mut huddle_event, event: &NodeEvent) {
    match event {
        NodeEvent::Talk {
            from,
            queue,
            seq,
            value,
        } => {
            clear(out, HUDDLE_EVENT_TALK_DELIVERED);
            out.robot = *from;
            write_text(&mut out.name, queue);
            out.seq = *seq;
            put_value(out, value);
        }
        NodeEvent::TalkLost {
            from,
            queue,
            first,
            last,
        } => {
            clear(out, HUDDLE_EVENT_TALK_GIVEN_UP);
            out.robot = *from;
            write_text(&mut out.name, queue);
            out.seq = *first;
            out.last = *last;
        }
        NodeEvent::Joined { robot, incarnation } => {
            clear(out, HUDDLE_EVENT_PEER_JOINED);
            out.robot = *robot;
            out.incarnation = *incarnation;
        }
        NodeEvent::Departed { robot } => {
            clear(out, HUDDLE_EVENT_PEER_DEPARTED);
            out.robot = *robot;
        }
        NodeEvent::Restarted { robot, incarnation } => {
            clear(out, HUDDLE_EVENT_PEER_RESTARTED);
            out.robot = *robot;
            out.incarnation = *incarnation;
        }
        NodeEvent::Lagged(n) => {
            clear(out, HUDDLE_EVENT_LAGGED);
            out.count = *n;
        }
        NodeEvent::Changed { key, owner, value } => {
            clear(out, HUDDLE_EVENT_VALUE_CHANGED);
            out.robot = *owner;
            write_text(&mut out.name, key);
            put_value(out, value);
        }
        NodeEvent::IdConflict { robot, incarnation } => {
            clear(out, HUDDLE_EVENT_ID_CONFLICT);
            out.robot = *robot;
            out.incarnation = *incarnation;
        }
        NodeEvent::Other { robot, description } => {
            clear(out, HUDDLE_EVENT_OTHER);
            out.robot = *robot;
            write_text(&mut out.name, description);
        }
    }
}

/// Fills `out` from a replica event.
pub(crate) fn fill_replica_event(out: &mut huddle_event, event: &Event) {
    match event {
        Event::ValueChanged { key } => {
            clear(out, HUDDLE_EVENT_VALUE_CHANGED);
            write_text(&mut out.name, &key.to_string());
        }
        Event::TalkDelivered {
            queue,
            from,
            seq,
            value,
        } => fill_node_event(
            out,
            &NodeEvent::Talk {
                from: *from,
                queue: queue.clone(),
                seq: *seq,
                value: value.clone(),
            },
        ),
        Event::TalkGivenUp {
            queue,
            from,
            first,
            last,
        } => fill_node_event(
            out,
            &NodeEvent::TalkLost {
                from: *from,
                queue: queue.clone(),
                first: *first,
                last: *last,
            },
        ),
        Event::PeerJoined { robot, incarnation } => fill_node_event(
            out,
            &NodeEvent::Joined {
                robot: *robot,
                incarnation: *incarnation,
            },
        ),
        Event::PeerRestarted {
            robot,
            new_incarnation,
            ..
        } => fill_node_event(
            out,
            &NodeEvent::Restarted {
                robot: *robot,
                incarnation: *new_incarnation,
            },
        ),
        Event::PeerDeparted { robot } => {
            fill_node_event(out, &NodeEvent::Departed { robot: *robot })
        }
        Event::IncarnationConflict { robot, other, .. } => fill_node_event(
            out,
            &NodeEvent::IdConflict {
                robot: *robot,
                incarnation: *other,
            },
        ),
        // Dropped frames, and any event a later comms adds: described, never lost.
        other => {
            if let Event::FrameDropped { reason, .. } = other {
                clear(out, HUDDLE_EVENT_FRAME_DROPPED);
                write_text(&mut out.name, reason.name());
            } else {
                clear(out, HUDDLE_EVENT_OTHER);
                write_text(&mut out.name, &format!("{other:?}"));
            }
        }
    }
}
