//! NACKs and re-sends under attack: unkeyed talk heads that open gaps, and spoofed NACKs.
//! The NACK state stays bounded, the robot's own news keeps its share of a budget's
//! frames, and in bytes on the air NACKs from gaps and re-sends from NACKs each cost at
//! most twice what caused them.
//!
//! How amplification is measured: the victim's `bytes_out` over the attack, less its
//! `bytes_out` over the same run without the attack (its own refreshes and heartbeats),
//! against the bytes of the attacker's datagrams.

use super::tests::{addr, robot, t};
use super::*;
use crate::talk::NACKS_WAITING_MAX;
use crate::wire::{decode_frame, FrameWriter, Item};

/// One second of the attack at second `s`: `senders` spoofed ids (10..), each with
/// `queues` queues whose heads claim 10 more messages every second (a gap each), packed
/// into frames of at most `mtu` bytes.
fn gap_heads(s: u64, senders: u8, queues: usize, mtu: usize) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for sender in 10..10 + senders {
        let mut q = 0;
        let mut seq = s * 100;
        while q < queues {
            seq += 1;
            let mut w = FrameWriter::new(7, sender, 5, seq, mtu, None);
            while q < queues {
                let queue = format!("q{q}");
                if !w.push(ItemRef::TalkHead {
                    queue: &queue,
                    first: 1,
                    last: 10 * (s + 1),
                }) {
                    break;
                }
                q += 1;
            }
            out.push(w.finish());
        }
    }
    out
}

/// Runs `victim` for `secs`, news (`*.var.ball`) every 100 ms, timers every 20 ms, and
/// `attack(s)` delivered at the start of each second. Returns (attack bytes, frames out).
fn run(
    victim: &mut Replica,
    secs: u64,
    mut attack: impl FnMut(u64) -> Vec<Vec<u8>>,
    mut check: impl FnMut(&Replica),
) -> (usize, Vec<Vec<u8>>) {
    let mut attack_bytes = 0;
    let mut out = Vec::new();
    for ms in (0..secs * 1000).step_by(20) {
        let now = t(ms);
        if ms % 1000 == 0 {
            for f in attack(ms / 1000) {
                attack_bytes += f.len();
                victim.handle_datagram(now, addr(), &f);
            }
        }
        if ms % 100 == 0 {
            victim
                .set(now, "*.var.ball", Value::Int(ms as i64))
                .unwrap();
        }
        victim.handle_timeout(now);
        while let Some(tx) = victim.poll_transmit() {
            out.push(tx.payload);
        }
        check(victim);
    }
    (attack_bytes, out)
}

fn budgeted(id: u8) -> Replica {
    let cfg = ReplicaConfig::new(id, 7).with_budget(&BudgetSpec::SPL, 5);
    Replica::new(cfg, 1, t(0)).unwrap()
}

/// 100 spoofed senders × 64 queues, a gap in each once a second, for 30 s, at an SPL
/// robot: NACKs waiting stay bounded, and its own value rides in its frames.
#[test]
fn under_a_budget_gaps_from_100_spoofed_senders_neither_pile_up_nor_crowd_out_the_news() {
    let mut victim = budgeted(1);
    let mut most_waiting = 0;
    let (_, frames) = run(
        &mut victim,
        30,
        |s| gap_heads(s, 100, 64, 128),
        |v| most_waiting = most_waiting.max(v.nacks_out.len()),
    );
    assert!(
        most_waiting <= NACKS_WAITING_MAX,
        "{most_waiting} NACK items waited for a frame"
    );
    let with_news = frames
        .iter()
        .filter(|f| {
            decode_frame(f, 7, None)
                .unwrap()
                .items
                .iter()
                .any(|i| matches!(i, Item::Update { path, .. } if path == "ball"))
        })
        .count();
    // An SPL share is a frame every 5 s.
    assert!(frames.len() >= 5, "{} frames in 30 s", frames.len());
    assert!(
        with_news * 2 >= frames.len(),
        "the robot's own value rode in {with_news} of its {} frames",
        frames.len()
    );
}

/// The same gaps at a robot without a budget (10 senders, 10 s): the NACKs it sends cost
/// at most twice the attacker's bytes.
#[test]
fn nacks_from_spoofed_gaps_cost_at_most_twice_the_attackers_bytes() {
    let mut quiet = robot(1, 1);
    let (_, baseline) = run(&mut quiet, 10, |_| Vec::new(), |_| {});
    let baseline: usize = baseline.iter().map(Vec::len).sum();
    let mut victim = robot(1, 1);
    let (attack, frames) = run(&mut victim, 10, |s| gap_heads(s, 10, 64, 1200), |_| {});
    let out: usize = frames.iter().map(Vec::len).sum::<usize>() - baseline;
    println!(
        "gaps -> NACKs: {attack} bytes in, {out} bytes out ({:.2}x)",
        out as f64 / attack as f64
    );
    assert!(
        out <= 2 * attack,
        "{out} bytes of NACKs for {attack} bytes of spoofed heads"
    );
    assert!(victim.stats().nacks_sent > 0, "the gaps were NACKed");
}

/// Spoofed NACKs (sender 9, small frames asking for 256 messages of 1 kB each): the
/// re-sends cost at most twice the NACKs' bytes.
#[test]
fn resends_for_spoofed_nacks_cost_at_most_twice_the_nacks_bytes() {
    let mut victim = robot(1, 1);
    for i in 0..256u64 {
        victim
            .post(t(4 * i), "*.talk.q", Value::Bytes(vec![0xab; 1000]))
            .unwrap();
    }
    while victim.poll_transmit().is_some() {}
    let before = victim.stats().bytes_out;
    let mut nack_bytes = 0;
    for i in 0..2_000u64 {
        let mut w = FrameWriter::new(7, 9, 9 << 16, i + 1, 1200, None);
        w.push(ItemRef::Nack {
            target: 1,
            queue: "q",
            first: 1,
            last: 256,
        });
        let f = w.finish();
        nack_bytes += f.len();
        victim.handle_datagram(t(2_000 + i), addr(), &f);
        while victim.poll_transmit().is_some() {}
    }
    let out = (victim.stats().bytes_out - before) as usize;
    println!(
        "NACKs -> re-sends: {nack_bytes} bytes in, {out} bytes out ({:.2}x)",
        out as f64 / nack_bytes as f64
    );
    // Heartbeats and heads over those 2 s are in `out` too (a few hundred bytes).
    assert!(
        out <= 2 * nack_bytes + 1024,
        "{out} bytes of re-sends for {nack_bytes} bytes of spoofed NACKs"
    );
}
