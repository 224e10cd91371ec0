//! The peer table: every robot heard, its incarnation (and the retired ones, whose late
//! frames are dropped), when it was last heard, its talk inboxes, and the replay window
//! that keyed teams check every frame against.

use std::collections::{BTreeMap, VecDeque};

use crate::stats::{DropReason, PeerInfo};
use crate::talk::Inbox;
use crate::time::Instant;

use super::{Event, Replica};

/// How many of a peer's past incarnations are remembered (their late frames are dropped).
const RETIRED_INCARNATIONS: usize = 8;

/// Replay protection: the highest sequence number seen and a 64-frame window below it.
#[derive(Debug, Default)]
pub(super) struct ReplayWindow {
    highest: u64,
    seen: u64,
}

impl ReplayWindow {
    fn accept(&mut self, seq: u64) -> bool {
        if seq > self.highest {
            let shift = seq - self.highest;
            self.seen = if shift >= 64 { 0 } else { self.seen << shift };
            self.seen |= 1;
            self.highest = seq;
            return true;
        }
        let back = self.highest - seq;
        if back >= 64 || self.seen & (1 << back) != 0 {
            return false;
        }
        self.seen |= 1 << back;
        true
    }
}

#[derive(Debug)]
pub(super) struct Peer {
    incarnation: u64,
    retired: VecDeque<u64>,
    pub(super) last_heard: Instant,
    pub(super) present: bool,
    frames: u64,
    replay: ReplayWindow,
    pub(super) inboxes: BTreeMap<String, Inbox>,
}

impl Replica {
    /// Every robot heard so far.
    pub fn peers(&self) -> impl Iterator<Item = PeerInfo> + '_ {
        self.peers.iter().map(|(&robot, p)| PeerInfo {
            robot,
            incarnation: p.incarnation,
            last_heard: p.last_heard,
            present: p.present,
            frames: p.frames,
        })
    }

    /// Peer bookkeeping for a valid frame: join, restart, replay check.
    pub(super) fn admit(
        &mut self,
        now: Instant,
        sender: u8,
        incarnation: u64,
        seq: u64,
    ) -> Result<(), DropReason> {
        let keyed = self.key.is_some();
        let mut joined = true;
        let peer = match self.peers.get_mut(&sender) {
            None => {
                self.events.push_back(Event::PeerJoined {
                    robot: sender,
                    incarnation,
                });
                self.peers.entry(sender).or_insert(Peer {
                    incarnation,
                    retired: VecDeque::new(),
                    last_heard: now,
                    present: true,
                    frames: 0,
                    replay: ReplayWindow::default(),
                    inboxes: BTreeMap::new(),
                })
            }
            Some(peer) if peer.incarnation != incarnation => {
                if peer.retired.contains(&incarnation) {
                    return Err(DropReason::RetiredIncarnation);
                }
                let old = std::mem::replace(&mut peer.incarnation, incarnation);
                peer.retired.push_back(old);
                if peer.retired.len() > RETIRED_INCARNATIONS {
                    peer.retired.pop_front();
                }
                peer.replay = ReplayWindow::default();
                peer.present = true;
                // The old incarnation's queues can no longer be repaired.
                for (queue, mut inbox) in std::mem::take(&mut peer.inboxes) {
                    inbox.flush(&mut self.deliveries);
                    Self::hand_up_into(
                        &mut self.events,
                        &mut self.stats,
                        &mut self.deliveries,
                        sender,
                        &queue,
                    );
                }
                self.events.push_back(Event::PeerRestarted {
                    robot: sender,
                    old_incarnation: old,
                    new_incarnation: incarnation,
                });
                peer
            }
            Some(peer) => {
                joined = !peer.present;
                if joined {
                    peer.present = true;
                    self.events.push_back(Event::PeerJoined {
                        robot: sender,
                        incarnation,
                    });
                }
                peer
            }
        };
        if keyed && !peer.replay.accept(seq) {
            return Err(DropReason::Replay);
        }
        peer.last_heard = now;
        peer.frames += 1;
        self.stats.last_heard.insert(sender, now);
        if joined {
            self.refresh_for_newcomer(now);
        }
        Ok(())
    }
}
