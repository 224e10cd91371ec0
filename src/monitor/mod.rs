//! Watching a team from outside: a listen-only member of its group ([`listen`]) and
//! recordings of its traffic ([`pcapng`]), for `huddle record`, `huddle replay` and
//! `huddle sim --record`.

pub mod listen;
pub mod model;
pub mod pcapng;
pub mod server;
pub mod tap;
