//! The simulator: nodes, links, groups, virtual time and the event queue.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashSet, VecDeque};
use std::fmt;
use std::io::{self, Write};
use std::sync::Arc;

use crate::clock::NodeClock;
use crate::impairment::{ConfigError, LinkConfig, UplinkConfig};
use crate::link::{DropReason, LinkModel, Uplink, Verdict};
use crate::preset::Preset;
use crate::seed::{self, Domain};
use crate::stats::LinkStats;
use crate::time::Time;
use crate::trace::{payload_hash, Trace, TraceKind};

/// A node (a robot). Ids are handed out from 1 by [`Sim::add_node`], so the first five
/// nodes are 1–5 and appear in pcap captures as 10.0.0.1–10.0.0.5.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(pub u16);

/// A multicast group. Ids are handed out from 1 by [`Sim::add_group`]; group 1 appears
/// in pcap captures as 224.0.0.1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct GroupId(pub u16);

impl fmt::Display for NodeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "n{}", self.0)
    }
}

impl fmt::Display for GroupId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "g{}", self.0)
    }
}

/// Where a packet is addressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Dest {
    /// One node (unicast).
    Node(NodeId),
    /// Every member of a group (multicast).
    Group(GroupId),
}

impl fmt::Display for Dest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Dest::Node(n) => n.fmt(f),
            Dest::Group(g) => g.fmt(f),
        }
    }
}

/// A packet as a node receives it.
#[derive(Debug, Clone, PartialEq)]
pub struct Delivery {
    /// Arrival, global time.
    pub at: Time,
    /// Arrival on the receiving node's own clock: what its receive timestamp reads.
    pub local_at: Time,
    /// Sender.
    pub from: NodeId,
    /// How it was addressed (this node, or a group it belongs to).
    pub dest: Dest,
    /// Send time, global (for statistics; a real node cannot know it).
    pub sent_at: Time,
    /// Whether this is the extra copy made by duplication.
    pub duplicate: bool,
    /// The payload, shared by every receiver of the transmission.
    pub bytes: Arc<[u8]>,
}

/// A change to the network, applied now ([`Sim::apply`]) or on schedule ([`Sim::at`]).
/// The verbs follow turmoil: `partition` cuts, `repair` restores.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Cut both directions between two nodes.
    Partition(NodeId, NodeId),
    /// Cut one direction only.
    PartitionOneway {
        /// Sender side.
        from: NodeId,
        /// Receiver side.
        to: NodeId,
    },
    /// Cut a node off from everyone (its own loopback keeps working).
    Isolate(NodeId),
    /// Undo [`Action::Partition`] between two nodes.
    Repair(NodeId, NodeId),
    /// Undo [`Action::PartitionOneway`].
    RepairOneway {
        /// Sender side.
        from: NodeId,
        /// Receiver side.
        to: NodeId,
    },
    /// Undo [`Action::Isolate`].
    Rejoin(NodeId),
    /// Undo every partition and isolation.
    Heal,
    /// Retune one link (its random stream carries on; other links are untouched).
    SetLink {
        /// Sender side.
        from: NodeId,
        /// Receiver side.
        to: NodeId,
        /// The new configuration.
        config: Box<LinkConfig>,
    },
    /// Retune a node's shared uplink.
    SetUplink(NodeId, UplinkConfig),
    /// Change a node's clock.
    SetClock(NodeId, NodeClock),
}

impl fmt::Display for Action {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Action::Partition(a, b) => write!(f, "partition {a} {b}"),
            Action::PartitionOneway { from, to } => write!(f, "partition-oneway {from}->{to}"),
            Action::Isolate(n) => write!(f, "isolate {n}"),
            Action::Repair(a, b) => write!(f, "repair {a} {b}"),
            Action::RepairOneway { from, to } => write!(f, "repair-oneway {from}->{to}"),
            Action::Rejoin(n) => write!(f, "rejoin {n}"),
            Action::Heal => write!(f, "heal"),
            Action::SetLink { from, to, config } => write!(f, "set-link {from}->{to} {config}"),
            Action::SetUplink(n, c) => {
                write!(f, "set-uplink {n} loss={} burst={:?}", c.loss, c.burst)
            }
            Action::SetClock(n, c) => write!(
                f,
                "set-clock {n} offset={}ns drift={}ppm",
                c.offset().as_nanos(),
                c.drift_ppm()
            ),
        }
    }
}

/// Why a packet could not be sent.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SendError {
    /// No such node (as sender or receiver).
    #[error("unknown node {0}")]
    UnknownNode(NodeId),
    /// No such group.
    #[error("unknown group {0}")]
    UnknownGroup(GroupId),
    /// `send_at` was given a time before the simulator's current time.
    #[error("cannot send at {at}: the simulation is already at {now}")]
    InPast {
        /// The requested time.
        at: Time,
        /// The current time.
        now: Time,
    },
}

/// Why a change to the network (an [`Action`], a group change) was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ActionError {
    /// No such node.
    #[error("unknown node {0}")]
    UnknownNode(NodeId),
    /// No such group.
    #[error("unknown group {0}")]
    UnknownGroup(GroupId),
    /// The new link or uplink configuration is invalid.
    #[error("invalid configuration: {0}")]
    Config(#[from] ConfigError),
    /// [`Sim::at`] was given a time before the current time.
    #[error("cannot schedule at {at}: the simulation is already at {now}")]
    InPast {
        /// The requested time.
        at: Time,
        /// The current time.
        now: Time,
    },
}

/// Configures a [`Sim`]: seed, default link and uplink, loopback, trace recording.
#[derive(Debug, Clone)]
pub struct SimBuilder {
    seed: u64,
    link: LinkConfig,
    uplink: UplinkConfig,
    multicast_loop: bool,
    record_trace: bool,
}

impl Default for SimBuilder {
    fn default() -> Self {
        SimBuilder {
            seed: 0,
            link: LinkConfig::default(),
            uplink: UplinkConfig::default(),
            multicast_loop: true,
            record_trace: true,
        }
    }
}

impl SimBuilder {
    /// The master seed (default 0). Each link and uplink gets its own stream from it.
    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    /// Starts every link and uplink from a preset's parts.
    pub fn preset(mut self, preset: Preset) -> Self {
        self.link = preset.link();
        self.uplink = preset.uplink();
        self
    }

    /// The configuration of every link created from now on (default: perfect).
    pub fn link(mut self, config: LinkConfig) -> Self {
        self.link = config;
        self
    }

    /// The shared uplink of every node (default: lossless).
    pub fn uplink(mut self, config: UplinkConfig) -> Self {
        self.uplink = config;
        self
    }

    /// Whether a sender in a group receives its own multicast, at once and unimpaired,
    /// as with `IP_MULTICAST_LOOP` on (default: on).
    pub fn multicast_loop(mut self, on: bool) -> Self {
        self.multicast_loop = on;
        self
    }

    /// Whether the trace keeps every event (default: on; the hash is kept regardless).
    pub fn record_trace(mut self, on: bool) -> Self {
        self.record_trace = on;
        self
    }

    /// Builds an empty simulator at time zero.
    pub fn build(self) -> Result<Sim, ConfigError> {
        self.link.validate()?;
        self.uplink.validate()?;
        Ok(Sim {
            seed: self.seed,
            now: Time::ZERO,
            default_link: self.link,
            default_uplink: self.uplink,
            multicast_loop: self.multicast_loop,
            nodes: Vec::new(),
            links: Vec::new(),
            groups: Vec::new(),
            queue: BinaryHeap::new(),
            slots: Vec::new(),
            free_slots: Vec::new(),
            order: 0,
            next_tx: 0,
            cut: HashSet::new(),
            isolated_count: 0,
            trace: Trace::new(self.record_trace),
        })
    }
}

struct Node {
    clock: NodeClock,
    uplink: Uplink,
    isolated: bool,
    inbox: VecDeque<Delivery>,
}

struct LinkState {
    model: LinkModel,
    stats: LinkStats,
    next_seq: u64,
    max_delivered_seq: Option<u64>,
}

struct Arrival {
    tx: u64,
    from: NodeId,
    to: NodeId,
    seq: u64,
    dest: Dest,
    sent_at: Time,
    duplicate: bool,
    bytes: Arc<[u8]>,
}

enum Event {
    Arrive(Arrival),
    Send {
        from: NodeId,
        dest: Dest,
        bytes: Arc<[u8]>,
    },
    Act(Action),
}

/// A queue entry; the event itself waits in `Sim::slots` so that heap moves stay small.
/// Ordered by time, then insertion order (unique), so the queue, a min-heap through
/// [`Reverse`], runs events at the same time first-in first-out.
#[derive(PartialEq, Eq, PartialOrd, Ord)]
struct Scheduled {
    at: Time,
    /// Insertion order: events at the same time run first-in first-out.
    order: u64,
    slot: usize,
}

/// A deterministic network in virtual time.
///
/// Time only moves when told to ([`Sim::step`], [`Sim::run_until`]); it jumps from event
/// to event. Sends happen at the current time ([`Sim::send`]) or are scheduled
/// ([`Sim::send_at`]); arrivals pile up in each node's inbox until taken ([`Sim::recv`]).
/// See the crate documentation for how a harness interleaves it with protocol timers.
pub struct Sim {
    seed: u64,
    now: Time,
    default_link: LinkConfig,
    default_uplink: UplinkConfig,
    multicast_loop: bool,
    nodes: Vec<Node>,
    /// `links[from][to]`, by node index (id − 1).
    links: Vec<Vec<LinkState>>,
    /// Members of each group, sorted, by group index (id − 1).
    groups: Vec<Vec<NodeId>>,
    queue: BinaryHeap<Reverse<Scheduled>>,
    /// Events by slot; `None` slots are listed in `free_slots` for reuse.
    slots: Vec<Option<Event>>,
    free_slots: Vec<usize>,
    order: u64,
    next_tx: u64,
    /// One-way cuts `(from, to)`.
    cut: HashSet<(NodeId, NodeId)>,
    isolated_count: usize,
    trace: Trace,
}

impl fmt::Debug for Sim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Sim")
            .field("seed", &self.seed)
            .field("now", &self.now)
            .field("nodes", &self.nodes.len())
            .field("groups", &self.groups.len())
            .field("pending_events", &self.queue.len())
            .finish_non_exhaustive()
    }
}

impl Sim {
    /// A builder with a perfect network and seed 0.
    pub fn builder() -> SimBuilder {
        SimBuilder::default()
    }

    /// The master seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The current global time.
    pub fn now(&self) -> Time {
        self.now
    }

    /// Adds a node with an ideal clock; links to and from it get the default config.
    ///
    /// # Panics
    /// Beyond 65,535 nodes (ids are 16-bit).
    pub fn add_node(&mut self) -> NodeId {
        let id = NodeId(u16::try_from(self.nodes.len() + 1).expect("at most 65,535 nodes"));
        let uplink = Uplink::new(
            self.default_uplink,
            seed::stream(self.seed, Domain::Uplink, id.0, 0),
        )
        .expect("default uplink validated by the builder");
        self.nodes.push(Node {
            clock: NodeClock::IDEAL,
            uplink,
            isolated: false,
            inbox: VecDeque::new(),
        });
        let new_link = |seed: u64, default: &LinkConfig, from: NodeId, to: NodeId| LinkState {
            model: LinkModel::with_rng(
                default.clone(),
                seed::stream(seed, Domain::Link, from.0, to.0),
            )
            .expect("default link validated by the builder"),
            stats: LinkStats::default(),
            next_seq: 0,
            max_delivered_seq: None,
        };
        for (i, row) in self.links.iter_mut().enumerate() {
            row.push(new_link(
                self.seed,
                &self.default_link,
                NodeId(i as u16 + 1),
                id,
            ));
        }
        let row = (1..=id.0)
            .map(|to| new_link(self.seed, &self.default_link, id, NodeId(to)))
            .collect();
        self.links.push(row);
        id
    }

    /// Adds `count` nodes and returns their ids.
    pub fn add_nodes(&mut self, count: usize) -> Vec<NodeId> {
        (0..count).map(|_| self.add_node()).collect()
    }

    /// Every node, in id order.
    pub fn nodes(&self) -> impl ExactSizeIterator<Item = NodeId> {
        (1..=self.nodes.len() as u16).map(NodeId)
    }

    /// Adds a multicast group with these members.
    pub fn add_group(&mut self, members: &[NodeId]) -> Result<GroupId, ActionError> {
        for &m in members {
            self.node(m)?;
        }
        let id = GroupId(u16::try_from(self.groups.len() + 1).expect("at most 65,535 groups"));
        let mut members = members.to_vec();
        members.sort_unstable();
        members.dedup();
        self.groups.push(members);
        Ok(id)
    }

    /// Adds `node` to `group` (no effect if already a member).
    pub fn join(&mut self, node: NodeId, group: GroupId) -> Result<(), ActionError> {
        self.node(node)?;
        let members = self.members_mut(group)?;
        if let Err(at) = members.binary_search(&node) {
            members.insert(at, node);
        }
        Ok(())
    }

    /// Removes `node` from `group` (no effect if not a member).
    pub fn leave(&mut self, node: NodeId, group: GroupId) -> Result<(), ActionError> {
        self.node(node)?;
        let members = self.members_mut(group)?;
        if let Ok(at) = members.binary_search(&node) {
            members.remove(at);
        }
        Ok(())
    }

    /// The members of a group, sorted.
    pub fn group_members(&self, group: GroupId) -> Option<&[NodeId]> {
        self.groups
            .get(usize::from(group.0).wrapping_sub(1))
            .map(Vec::as_slice)
    }

    fn members_mut(&mut self, group: GroupId) -> Result<&mut Vec<NodeId>, ActionError> {
        self.groups
            .get_mut(usize::from(group.0).wrapping_sub(1))
            .ok_or(ActionError::UnknownGroup(group))
    }

    fn index(&self, node: NodeId) -> Option<usize> {
        let i = usize::from(node.0).wrapping_sub(1);
        (i < self.nodes.len()).then_some(i)
    }

    fn node(&self, node: NodeId) -> Result<usize, ActionError> {
        self.index(node).ok_or(ActionError::UnknownNode(node))
    }

    /// A node's clock.
    pub fn node_clock(&self, node: NodeId) -> Option<NodeClock> {
        self.index(node).map(|i| self.nodes[i].clock)
    }

    /// The configuration of the link `from → to`.
    pub fn link_config(&self, from: NodeId, to: NodeId) -> Option<&LinkConfig> {
        Some(
            self.links[self.index(from)?][self.index(to)?]
                .model
                .config(),
        )
    }

    /// The statistics of the link `from → to` (`from == to`: multicast loopback).
    pub fn link_stats(&self, from: NodeId, to: NodeId) -> Option<&LinkStats> {
        Some(&self.links[self.index(from)?][self.index(to)?].stats)
    }

    /// Every link's statistics as `(from, to, stats)`, loopback included.
    pub fn all_link_stats(&self) -> impl Iterator<Item = (NodeId, NodeId, &LinkStats)> {
        self.links.iter().enumerate().flat_map(|(f, row)| {
            row.iter()
                .enumerate()
                .map(move |(t, l)| (NodeId(f as u16 + 1), NodeId(t as u16 + 1), &l.stats))
        })
    }

    /// Statistics of all links between distinct nodes, merged (loopback excluded).
    pub fn network_stats(&self) -> LinkStats {
        let mut total = LinkStats::default();
        for (from, to, stats) in self.all_link_stats() {
            if from != to {
                total.merge(stats);
            }
        }
        total
    }

    /// The trace so far.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// Starts or stops keeping trace events (the hash is always kept).
    pub fn set_trace_recording(&mut self, on: bool) {
        self.trace.set_recording(on);
    }

    /// Writes the recorded trace as text lines.
    pub fn write_trace<W: Write>(&self, out: W) -> io::Result<()> {
        self.trace.write_text(out)
    }

    /// Writes the recorded deliveries as a pcap file (see [`crate::pcap`]).
    pub fn write_pcap<W: Write>(&self, out: W) -> io::Result<()> {
        crate::pcap::write_pcap(&self.trace, out)
    }

    /// Takes the oldest packet waiting at `node`, if any (`None` for an unknown node).
    pub fn recv(&mut self, node: NodeId) -> Option<Delivery> {
        let i = self.index(node)?;
        self.nodes[i].inbox.pop_front()
    }

    /// Takes every packet waiting at `node`, oldest first.
    pub fn drain(&mut self, node: NodeId) -> impl Iterator<Item = Delivery> + '_ {
        let inbox = match self.index(node) {
            Some(i) => Some(&mut self.nodes[i].inbox),
            None => None,
        };
        inbox.into_iter().flat_map(|q| q.drain(..))
    }

    /// How many packets wait at `node`.
    pub fn pending(&self, node: NodeId) -> usize {
        self.index(node).map_or(0, |i| self.nodes[i].inbox.len())
    }

    /// Whether packets from `from` to `to` are currently cut off.
    pub fn is_cut(&self, from: NodeId, to: NodeId) -> bool {
        if from == to || (self.cut.is_empty() && self.isolated_count == 0) {
            return false;
        }
        let isolated = |n: NodeId| self.index(n).is_some_and(|i| self.nodes[i].isolated);
        isolated(from) || isolated(to) || self.cut.contains(&(from, to))
    }

    /// Sends `bytes` from `from` now; returns the transmission number used in the trace.
    /// A multicast reaches every member of the group but the sender, plus the sender
    /// itself if it is a member and multicast loop is on.
    pub fn send(
        &mut self,
        from: NodeId,
        dest: Dest,
        bytes: impl Into<Arc<[u8]>>,
    ) -> Result<u64, SendError> {
        self.check_send(from, dest)?;
        Ok(self.transmit(from, dest, bytes.into()))
    }

    /// Schedules a send at `at` (≥ now).
    pub fn send_at(
        &mut self,
        at: Time,
        from: NodeId,
        dest: Dest,
        bytes: impl Into<Arc<[u8]>>,
    ) -> Result<(), SendError> {
        self.check_send(from, dest)?;
        if at < self.now {
            return Err(SendError::InPast { at, now: self.now });
        }
        let bytes = bytes.into();
        self.schedule(at, Event::Send { from, dest, bytes });
        Ok(())
    }

    fn check_send(&self, from: NodeId, dest: Dest) -> Result<(), SendError> {
        self.index(from).ok_or(SendError::UnknownNode(from))?;
        match dest {
            Dest::Node(to) => self.index(to).map(|_| ()).ok_or(SendError::UnknownNode(to)),
            Dest::Group(g) => self
                .group_members(g)
                .map(|_| ())
                .ok_or(SendError::UnknownGroup(g)),
        }
    }

    /// Applies a fault verb now.
    pub fn apply(&mut self, action: Action) -> Result<(), ActionError> {
        self.check_action(&action)?;
        self.perform(action);
        Ok(())
    }

    /// Schedules a fault verb at `at` (≥ now); it runs after events already queued for
    /// the same instant.
    pub fn at(&mut self, at: Time, action: Action) -> Result<(), ActionError> {
        if at < self.now {
            return Err(ActionError::InPast { at, now: self.now });
        }
        self.check_action(&action)?;
        self.schedule(at, Event::Act(action));
        Ok(())
    }

    /// Cuts both directions between `a` and `b`, now.
    pub fn partition(&mut self, a: NodeId, b: NodeId) -> Result<(), ActionError> {
        self.apply(Action::Partition(a, b))
    }

    /// Cuts `from → to` only, now.
    pub fn partition_oneway(&mut self, from: NodeId, to: NodeId) -> Result<(), ActionError> {
        self.apply(Action::PartitionOneway { from, to })
    }

    /// Cuts `node` off from every other node, now.
    pub fn isolate(&mut self, node: NodeId) -> Result<(), ActionError> {
        self.apply(Action::Isolate(node))
    }

    /// Restores both directions between `a` and `b`, now.
    pub fn repair(&mut self, a: NodeId, b: NodeId) -> Result<(), ActionError> {
        self.apply(Action::Repair(a, b))
    }

    /// Undoes [`Sim::isolate`], now.
    pub fn rejoin(&mut self, node: NodeId) -> Result<(), ActionError> {
        self.apply(Action::Rejoin(node))
    }

    /// Undoes every partition and isolation, now.
    pub fn heal(&mut self) {
        self.perform(Action::Heal);
    }

    /// Retunes the link `from → to`, now.
    pub fn set_link(
        &mut self,
        from: NodeId,
        to: NodeId,
        config: LinkConfig,
    ) -> Result<(), ActionError> {
        self.apply(Action::SetLink {
            from,
            to,
            config: Box::new(config),
        })
    }

    /// Retunes `node`'s shared uplink, now.
    pub fn set_uplink(&mut self, node: NodeId, config: UplinkConfig) -> Result<(), ActionError> {
        self.apply(Action::SetUplink(node, config))
    }

    /// Sets `node`'s clock, now.
    pub fn set_clock(&mut self, node: NodeId, clock: NodeClock) -> Result<(), ActionError> {
        self.apply(Action::SetClock(node, clock))
    }

    fn check_action(&self, action: &Action) -> Result<(), ActionError> {
        match action {
            Action::Partition(a, b) | Action::Repair(a, b) => {
                self.node(*a)?;
                self.node(*b)?;
            }
            Action::PartitionOneway { from, to } | Action::RepairOneway { from, to } => {
                self.node(*from)?;
                self.node(*to)?;
            }
            Action::Isolate(n) | Action::Rejoin(n) | Action::SetClock(n, _) => {
                self.node(*n)?;
            }
            Action::Heal => {}
            Action::SetLink { from, to, config } => {
                self.node(*from)?;
                self.node(*to)?;
                config.validate()?;
            }
            Action::SetUplink(n, config) => {
                self.node(*n)?;
                config.validate()?;
            }
        }
        Ok(())
    }

    /// Applies a checked action.
    fn perform(&mut self, action: Action) {
        let idx = |sim: &Sim, n: NodeId| sim.index(n).expect("action checked");
        match &action {
            Action::Partition(a, b) => {
                self.cut.insert((*a, *b));
                self.cut.insert((*b, *a));
            }
            Action::PartitionOneway { from, to } => {
                self.cut.insert((*from, *to));
            }
            Action::Repair(a, b) => {
                self.cut.remove(&(*a, *b));
                self.cut.remove(&(*b, *a));
            }
            Action::RepairOneway { from, to } => {
                self.cut.remove(&(*from, *to));
            }
            Action::Isolate(n) | Action::Rejoin(n) => {
                let isolate = matches!(action, Action::Isolate(_));
                let i = idx(self, *n);
                if self.nodes[i].isolated != isolate {
                    self.nodes[i].isolated = isolate;
                    if isolate {
                        self.isolated_count += 1;
                    } else {
                        self.isolated_count -= 1;
                    }
                }
            }
            Action::Heal => {
                self.cut.clear();
                for node in &mut self.nodes {
                    node.isolated = false;
                }
                self.isolated_count = 0;
            }
            Action::SetLink { from, to, config } => {
                let (f, t) = (idx(self, *from), idx(self, *to));
                self.links[f][t]
                    .model
                    .set_config((**config).clone())
                    .expect("config checked");
            }
            Action::SetUplink(n, config) => {
                let i = idx(self, *n);
                self.nodes[i]
                    .uplink
                    .set_config(*config)
                    .expect("config checked");
            }
            Action::SetClock(n, clock) => {
                let i = idx(self, *n);
                self.nodes[i].clock = *clock;
            }
        }
        self.trace.push(self.now, TraceKind::Action(action));
    }

    /// When the next queued event happens, if any.
    pub fn next_event_time(&self) -> Option<Time> {
        self.queue.peek().map(|Reverse(s)| s.at)
    }

    /// Runs the next queued event, moving time to it; returns its time, or `None` (and
    /// time stays put) if nothing is queued.
    pub fn step(&mut self) -> Option<Time> {
        let Reverse(Scheduled { at, slot, .. }) = self.queue.pop()?;
        let event = self.slots[slot].take().expect("queued slots hold an event");
        self.free_slots.push(slot);
        self.now = at;
        match event {
            Event::Arrive(arrival) => self.arrive(arrival),
            Event::Send { from, dest, bytes } => {
                self.transmit(from, dest, bytes);
            }
            Event::Act(action) => self.perform(action),
        }
        Some(at)
    }

    /// Runs every event at or before `until` (including those they create), then sets
    /// the time to exactly `until`. Time never goes back: an earlier `until` does nothing.
    pub fn run_until(&mut self, until: Time) {
        while self.next_event_time().is_some_and(|t| t <= until) {
            self.step();
        }
        self.now = self.now.max(until);
    }

    /// `run_until(now + duration)`.
    pub fn run_for(&mut self, duration: std::time::Duration) {
        self.run_until(self.now + duration);
    }

    fn schedule(&mut self, at: Time, event: Event) {
        self.order += 1;
        let slot = match self.free_slots.pop() {
            Some(slot) => {
                self.slots[slot] = Some(event);
                slot
            }
            None => {
                self.slots.push(Some(event));
                self.slots.len() - 1
            }
        };
        self.queue.push(Reverse(Scheduled {
            at,
            order: self.order,
            slot,
        }));
    }

    fn transmit(&mut self, from: NodeId, dest: Dest, bytes: Arc<[u8]>) -> u64 {
        let tx = self.next_tx;
        self.next_tx += 1;
        self.trace.push(
            self.now,
            TraceKind::Send {
                tx,
                from,
                dest,
                len: bytes.len(),
                payload_hash: payload_hash(&bytes),
            },
        );
        let f = usize::from(from.0) - 1;
        match dest {
            Dest::Node(to) if to == from => self.loop_back(tx, from, dest, bytes),
            Dest::Node(to) => {
                let uplink = self.nodes[f].uplink.transmit(self.now);
                self.offer(tx, from, to, dest, &bytes, uplink, false);
            }
            Dest::Group(g) => {
                let uplink = self.nodes[f].uplink.transmit(self.now);
                let gi = usize::from(g.0) - 1;
                for m in 0..self.groups[gi].len() {
                    let to = self.groups[gi][m];
                    if to == from {
                        if self.multicast_loop {
                            self.loop_back(tx, from, dest, bytes.clone());
                        }
                    } else {
                        self.offer(tx, from, to, dest, &bytes, uplink, true);
                    }
                }
            }
        }
        tx
    }

    /// The sender's own copy: the kernel loops it back at once, unimpaired.
    fn loop_back(&mut self, tx: u64, node: NodeId, dest: Dest, bytes: Arc<[u8]>) {
        let i = usize::from(node.0) - 1;
        let link = &mut self.links[i][i];
        link.stats.sent += 1;
        let seq = link.next_seq;
        link.next_seq += 1;
        let arrival = Arrival {
            tx,
            from: node,
            to: node,
            seq,
            dest,
            sent_at: self.now,
            duplicate: false,
            bytes,
        };
        self.schedule(self.now, Event::Arrive(arrival));
    }

    #[allow(clippy::too_many_arguments)] // private; one call per receiver
    fn offer(
        &mut self,
        tx: u64,
        from: NodeId,
        to: NodeId,
        dest: Dest,
        bytes: &Arc<[u8]>,
        uplink: Result<(), DropReason>,
        multicast: bool,
    ) {
        let cut = self.is_cut(from, to);
        let now = self.now;
        let link = &mut self.links[usize::from(from.0) - 1][usize::from(to.0) - 1];
        link.stats.sent += 1;
        let seq = link.next_seq;
        link.next_seq += 1;
        let verdict = match uplink {
            Err(reason) => Verdict::Drop(reason),
            Ok(()) if cut => Verdict::Drop(DropReason::Partition),
            Ok(()) if multicast => link.model.transmit_multicast(now, bytes.len()),
            Ok(()) => link.model.transmit(now, bytes.len()),
        };
        match verdict {
            Verdict::Drop(reason) => {
                link.stats.record_loss(reason);
                self.trace.push(
                    now,
                    TraceKind::Drop {
                        tx,
                        from,
                        to,
                        seq,
                        reason,
                    },
                );
            }
            Verdict::Deliver { at, duplicate_at } => {
                if duplicate_at.is_some() {
                    link.stats.duplicated += 1;
                }
                for (at, duplicate) in
                    std::iter::once((at, false)).chain(duplicate_at.map(|d| (d, true)))
                {
                    let arrival = Arrival {
                        tx,
                        from,
                        to,
                        seq,
                        dest,
                        sent_at: now,
                        duplicate,
                        bytes: bytes.clone(),
                    };
                    self.schedule(at, Event::Arrive(arrival));
                }
            }
        }
    }

    fn arrive(&mut self, a: Arrival) {
        let now = self.now;
        let cut = self.is_cut(a.from, a.to);
        let t = usize::from(a.to.0) - 1;
        let link = &mut self.links[usize::from(a.from.0) - 1][t];
        if cut {
            // In the air when the cut came: lost.
            link.stats.record_loss(DropReason::Partition);
            self.trace.push(
                now,
                TraceKind::Drop {
                    tx: a.tx,
                    from: a.from,
                    to: a.to,
                    seq: a.seq,
                    reason: DropReason::Partition,
                },
            );
            return;
        }
        link.stats.record_delivery(now - a.sent_at);
        match link.max_delivered_seq {
            Some(max) if a.seq < max => link.stats.reordered += 1,
            Some(max) if a.seq == max => {}
            _ => link.max_delivered_seq = Some(a.seq),
        }
        let local_at = self.nodes[t].clock.to_local(now);
        self.trace.push(
            now,
            TraceKind::Deliver {
                tx: a.tx,
                from: a.from,
                to: a.to,
                seq: a.seq,
                dest: a.dest,
                sent_at: a.sent_at,
                local_at,
                duplicate: a.duplicate,
                bytes: a.bytes.clone(),
            },
        );
        self.nodes[t].inbox.push_back(Delivery {
            at: now,
            local_at,
            from: a.from,
            dest: a.dest,
            sent_at: a.sent_at,
            duplicate: a.duplicate,
            bytes: a.bytes,
        });
    }
}
