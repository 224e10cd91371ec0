//! The bridge's queryables: a `get` on the team's values answered from the replica, and
//! `@bridge/stats` / `@bridge/peers` (moved out of `run.rs` to keep it short).

use std::sync::Mutex;

use comms::{Key, Pattern, Scope};
use driver::Clock;
use zenoh::bytes::Encoding;
use zenoh::key_expr::KeyExpr;
use zenoh::query::Query;
use zenoh::Wait;

use super::{lock, Core};
use crate::keys::TeamKeys;

/// Answers a `get` on the team's values from the replica, ages at reply time.
pub(super) fn answer_values(core: &Mutex<Core>, clock: &Clock, query: &Query) {
    let replies = {
        let mut core = lock(core);
        core.io.queries += 1;
        if query.payload().is_some() {
            core.io.queries_refused += 1;
            drop(core);
            tracing::warn!(
                "refused a query on {} with a payload: the bridge is read-only",
                query.key_expr()
            );
            let _ = query.reply_err("huddle-bridge is read-only").wait();
            return;
        }
        let now = clock.now();
        let Ok(pattern) = Pattern::parse("+.var.#") else {
            return;
        };
        let entries: Vec<(Key, comms::Entry)> = core
            .replica
            .iter(&pattern)
            .filter(|(k, _)| matches!(k.scope(), Scope::Robot(_)))
            .map(|(k, e)| (k, e.clone()))
            .collect();
        let mut replies = Vec::new();
        for (key, entry) in entries {
            if let Some(sample) = core.exporter.sample(now, &key, &entry) {
                let matches = KeyExpr::try_from(sample.key.as_str())
                    .is_ok_and(|k| k.intersects(query.key_expr()));
                if matches {
                    replies.push(sample);
                }
            }
        }
        core.io.replies += replies.len() as u64;
        replies
    };
    for s in replies {
        let attachment = s.attachment();
        if let Err(e) = query
            .reply(s.key, s.payload)
            .encoding(Encoding::TEXT_PLAIN)
            .attachment(attachment)
            .wait()
        {
            tracing::debug!("reply: {e}");
        }
    }
}

/// Answers `@bridge/stats` and `@bridge/peers` (JSON).
pub(super) fn answer_bridge(core: &Mutex<Core>, clock: &Clock, keys: &TeamKeys, query: &Query) {
    let now = clock.now();
    let mut replies = Vec::new();
    {
        let mut core = lock(core);
        core.io.queries += 1;
        for (what, json) in [
            ("stats", core.stats_json(now)),
            ("peers", core.peers_json(now)),
        ] {
            let key = keys.bridge(what);
            if KeyExpr::try_from(key.as_str()).is_ok_and(|k| k.intersects(query.key_expr())) {
                replies.push((key, json.to_string()));
            }
        }
        core.io.replies += replies.len() as u64;
    }
    for (key, json) in replies {
        let _ = query
            .reply(key, json)
            .encoding(Encoding::APPLICATION_JSON)
            .wait();
    }
}
