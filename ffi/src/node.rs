//! The node: a `comms::Replica` with its multicast socket (`engine`), and the C-facing
//! side that calls it from any thread.
//!
//! Every call runs on the caller's thread under the node's lock: a `set` or `post` has
//! sent its frame when it returns, as `driver::Handle::set` has, without waking another
//! thread first. A thread of the node's own receives datagrams and runs the replica's
//! timers. Talk messages and peer changes are queued for `huddle_node_next_event`.

use std::ffi::{c_char, c_int};
use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use comms::{BudgetSpec, Entry, Key, PostError, ReplicaConfig, SetError, Value};
use driver::team::TeamLayerConfig;
use driver::{resolve_iface, DriverConfig, GameControllerConfig, SocketConfig, Transport};
use team::SendPolicy;

use crate::binding::{fill_binding, huddle_binding};
use crate::engine::Engine;
use crate::error::*;
use crate::event::{fill_node_event, huddle_event};
use crate::handles::Handles;
use crate::text::{read_opt_str, read_str};

/// A running node. Opaque: create it with `huddle_node_start`, release it with
/// `huddle_node_stop`.
#[allow(non_camel_case_types)]
pub struct huddle_node {
    _opaque: [u8; 0],
}

/// How to start a node. Zero every field first (`huddle_node_config cfg = {0};`): a zero
/// or NULL field means its default.
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_node_config {
    /// This robot's id, 1..=254; 0: the `ROBOT_ID` environment variable.
    pub robot_id: u8,
    /// The team's id; frames of other teams are dropped.
    pub team_id: u8,
    /// The team's IPv4 multicast group (multicast only); NULL: `"224.0.0.1"`.
    pub group_address: *const c_char,
    /// The team's UDP port; 0: 2000 for multicast, 10000 + `team_id` (the RoboCup SPL
    /// team port) for broadcast and unicast.
    pub group_port: u16,
    /// The interface, by IPv4 address or name (`"wlan0"`); NULL: `"127.0.0.1"`, so
    /// nothing leaves the machine unless an interface is named.
    pub interface_address: *const c_char,
    /// Every global value is re-sent this often (ms); 0: 100.
    pub refresh_ms: u32,
    /// A file holding the team key (trailing whitespace ignored); NULL: no team key.
    pub key_file: *const c_char,
    /// A directory with `config.dat` and `config-<id>.dat`; NULL: no config files.
    pub config_dir: *const c_char,
    /// How frames reach the team, as `huddle daemon --transport`:
    /// `HUDDLE_TRANSPORT_MULTICAST` (0, to `group_address`), `HUDDLE_TRANSPORT_BROADCAST`
    /// (to the interface's broadcast address, RoboCup SPL; `127.255.255.255` on
    /// loopback) or `HUDDLE_TRANSPORT_UNICAST` (to each of `peers` only).
    pub transport: i32,
    /// Broadcast address of the broadcast transport (`"10.0.255.255"`); NULL: the
    /// interface's.
    pub broadcast_address: *const c_char,
    /// Teammates (`"10.0.0.12:10005"`) that also get every frame by unicast (with the
    /// unicast transport: only they). Unicast is received on `<interface>:<port>` from
    /// these addresses only. NULL when `peer_count` is 0.
    pub peers: *const *const c_char,
    /// How many strings `peers` points to.
    pub peer_count: usize,
    /// The team's message budget, as `huddle daemon --budget`: `"spl"` (1200 messages per
    /// 20-minute game, frames of at most 128 bytes), `"humanoid"` (12,000, 512 bytes) or
    /// `"N/DURATION"` (`"600/10min"`). This robot spends its share (`team_size`), paced
    /// over the game clock (`huddle_node_set_game_clock`; from the start by default), a
    /// fifth kept for priority items (`huddle_node_set_priority`). NULL: no budget.
    pub budget: *const c_char,
    /// Robots sharing the budget; 0: 5.
    pub team_size: u8,
    /// Non-zero: pool the budget with the team (`huddle daemon --budget-pool`): only when
    /// every robot of the team runs huddle with the same budget.
    pub budget_pool: u8,
    /// Non-zero: listen this long (ms) at the start for another robot sending with this
    /// `robot_id`, and refuse to start (`HUDDLE_E_ID_CONFLICT`) if one is heard; a few
    /// refresh periods suffice (teammates send at least once per refresh). 0: start at
    /// once; a conflict is still reported later as `HUDDLE_EVENT_ID_CONFLICT`.
    pub id_check_ms: u32,
    /// Non-zero: do not run the team layer (`huddle daemon --no-team-layer`): the
    /// `local.var.robot.*` keys are then plain keys, unchecked, and nothing writes
    /// `local.var.team.*`. By default the node runs it as the daemon does
    /// (docs/team-layer.md), dormant until the program writes a pose or odometry.
    pub no_team_layer: u8,
    /// The team layer's sending policy, as `huddle daemon --policy`: `"voi"`,
    /// `"baseline"` or `"every"`; NULL: `voi` under a budget, `every` without.
    pub team_policy: *const c_char,
    /// The GameController listener, as `huddle daemon --gamecontroller`:
    /// `HUDDLE_GC_AUTO` (0: on with the `"spl"` budget, and a node that cannot bind its
    /// port starts without it, saying so on stderr), `HUDDLE_GC_ON` (a node that cannot
    /// listen does not start) or `HUDDLE_GC_OFF`. It writes the GC's packets to
    /// `local.var.gc.*`, under a budget paces it by the GC's game clock and message count,
    /// and sends this robot's status (from `local.var.robot.pose`, `local.var.team.ball`,
    /// `local.var.robot.fallen`) to the GC's port 3939; `team_id` and `robot_id` are the
    /// team and player numbers.
    pub gamecontroller: i32,
    /// Where it listens (`"ADDR:PORT"`); NULL: `"0.0.0.0:3838"` (the GC broadcasts).
    pub gc_listen: *const c_char,
    /// The port status packets go to on the GC's address; 0: 3939.
    pub gc_status_port: u16,
}

/// `huddle_node_config.gamecontroller`: on with the `"spl"` budget (the default).
pub const HUDDLE_GC_AUTO: i32 = 0;
/// `huddle_node_config.gamecontroller`: on; the start fails if the port cannot be bound.
pub const HUDDLE_GC_ON: i32 = 1;
/// `huddle_node_config.gamecontroller`: off.
pub const HUDDLE_GC_OFF: i32 = 2;

/// `huddle_node_config.transport`: every frame to the multicast group (the default).
pub const HUDDLE_TRANSPORT_MULTICAST: i32 = 0;
/// `huddle_node_config.transport`: every frame to the interface's broadcast address on
/// the team port (RoboCup SPL: 10000 + team).
pub const HUDDLE_TRANSPORT_BROADCAST: i32 = 1;
/// `huddle_node_config.transport`: every frame to each listed peer only.
pub const HUDDLE_TRANSPORT_UNICAST: i32 = 2;

/// The C-facing side of a node: `Send + Sync`, shared by every calling thread.
type Node = Engine;

static NODES: Handles<Node> = Handles::new();

/// What a node runs: the driver's settings, the team layer's unless it is off, the
/// GameController listener's if it is on (and whether it was asked for).
struct NodeConfig {
    driver: DriverConfig,
    team: Option<TeamLayerConfig>,
    gc: Option<(GameControllerConfig, bool)>,
}

/// The settings checked and resolved on the caller's thread, so that a bad one fails
/// the start with a clear reason.
fn driver_config(cfg: &huddle_node_config) -> Result<NodeConfig, Failure> {
    let robot_id = match cfg.robot_id {
        0 => {
            let raw = std::env::var("ROBOT_ID").map_err(|_| {
                Failure::new(
                    HUDDLE_E_CONFIG,
                    "no robot id: set robot_id or the ROBOT_ID environment variable",
                )
            })?;
            raw.trim().parse::<u8>().map_err(|_| {
                Failure::new(
                    HUDDLE_E_CONFIG,
                    format!("ROBOT_ID={raw:?} is not a robot id 1..=254"),
                )
            })?
        }
        id => id,
    };
    if !comms::ROBOT_IDS.contains(&robot_id) {
        return Err(Failure::new(
            HUDDLE_E_CONFIG,
            format!("robot id {robot_id} is outside 1..=254"),
        ));
    }
    let refresh_ms = if cfg.refresh_ms == 0 {
        100
    } else {
        cfg.refresh_ms
    };
    let mut replica = ReplicaConfig::new(robot_id, cfg.team_id)
        .with_refresh_period(Duration::from_millis(refresh_ms.into()))
        .with_known_paths(team::known_paths());
    // SAFETY (all reads of the config's strings): the caller promises they are NULL or
    // NUL-terminated and alive for the call.
    let group = unsafe { read_opt_str(cfg.group_address, "group_address") }?;
    let iface =
        unsafe { read_opt_str(cfg.interface_address, "interface_address") }?.unwrap_or("127.0.0.1");
    let key_file = unsafe { read_opt_str(cfg.key_file, "key_file") }?;
    let config_dir = unsafe { read_opt_str(cfg.config_dir, "config_dir") }?;
    let broadcast = unsafe { read_opt_str(cfg.broadcast_address, "broadcast_address") }?;
    let budget = unsafe { read_opt_str(cfg.budget, "budget") }?;
    let policy = unsafe { read_opt_str(cfg.team_policy, "team_policy") }?;
    let gc_listen = unsafe { read_opt_str(cfg.gc_listen, "gc_listen") }?;
    // SAFETY: as above, for `peer_count` strings.
    let peers = unsafe { read_peers(cfg.peers, cfg.peer_count) }?;

    let transport = match cfg.transport {
        HUDDLE_TRANSPORT_MULTICAST => Transport::Multicast,
        HUDDLE_TRANSPORT_BROADCAST => Transport::Broadcast,
        HUDDLE_TRANSPORT_UNICAST => Transport::Unicast,
        other => {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                format!(
                    "transport {other} is not HUDDLE_TRANSPORT_MULTICAST, _BROADCAST or _UNICAST"
                ),
            ))
        }
    };
    let group = match (transport, group) {
        (Transport::Multicast, group) => {
            let group = group.unwrap_or("224.0.0.1");
            let group: Ipv4Addr = group.parse().map_err(|_| {
                Failure::new(
                    HUDDLE_E_NETWORK,
                    format!("group_address {group:?} is not an IPv4 address"),
                )
            })?;
            if !group.is_multicast() {
                return Err(Failure::new(
                    HUDDLE_E_NETWORK,
                    format!("group_address {group} is not a multicast address (224.0.0.0/4)"),
                ));
            }
            let port = if cfg.group_port == 0 { 2000 } else { cfg.group_port };
            SocketAddrV4::new(group, port)
        }
        (_, Some(group)) => {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                format!("group_address {group:?} is a multicast group, and the {transport} transport has none: leave it NULL"),
            ))
        }
        (_, None) => {
            let port = if cfg.group_port == 0 {
                10_000 + u16::from(cfg.team_id)
            } else {
                cfg.group_port
            };
            SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, port)
        }
    };
    let broadcast = match (transport, broadcast) {
        (_, None) => None,
        (Transport::Broadcast, Some(b)) => Some(b.parse::<Ipv4Addr>().map_err(|_| {
            Failure::new(
                HUDDLE_E_NETWORK,
                format!("broadcast_address {b:?} is not an IPv4 address"),
            )
        })?),
        (_, Some(_)) => {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                "broadcast_address is for the broadcast transport",
            ))
        }
    };
    if transport == Transport::Unicast && peers.is_empty() {
        return Err(Failure::new(
            HUDDLE_E_CONFIG,
            "the unicast transport sends to each peer only: give at least one in peers",
        ));
    }
    let iface = resolve_iface(iface)
        .map_err(|e| Failure::new(HUDDLE_E_NETWORK, format!("interface_address: {e}")))?;
    let team_size = if cfg.team_size == 0 { 5 } else { cfg.team_size };
    let mut budget_interval = None;
    let budget = budget
        .map(|spec| {
            spec.parse::<BudgetSpec>()
                .map_err(|e| Failure::new(HUDDLE_E_CONFIG, e.to_string()))
        })
        .transpose()?;
    if let Some(spec) = budget {
        budget_interval = Some(spec.share(usize::from(team_size)).interval());
        if spec.share(usize::from(team_size)).messages == 0 {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                format!("budget {spec}: a share of 0 messages for each of {team_size} robots"),
            ));
        }
        replica = replica.with_budget(&spec, usize::from(team_size));
        if cfg.budget_pool == 0 {
            replica.budget = replica.budget.map(comms::Budget::split);
        }
    }
    if let Some(file) = key_file {
        let bytes = std::fs::read(file)
            .map_err(|e| Failure::new(HUDDLE_E_IO, format!("cannot read key file {file}: {e}")))?;
        let key = bytes.trim_ascii_end();
        if key.is_empty() {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                format!("key file {file} is empty"),
            ));
        }
        replica = replica.with_team_key(key.to_vec());
    }
    let mut config = DriverConfig::new(replica);
    if let Some(dir) = config_dir {
        if !Path::new(dir).is_dir() {
            return Err(Failure::new(
                HUDDLE_E_IO,
                format!("config_dir {dir} is not a directory"),
            ));
        }
        let entries = driver::load_config(Path::new(dir), robot_id)
            .map_err(|e| Failure::new(HUDDLE_E_CONFIG, e.to_string()))?;
        config.start_values = entries.into_iter().map(|e| (e.key, e.value)).collect();
    }
    config.socket = SocketConfig {
        transport,
        group,
        broadcast,
        iface,
        ..SocketConfig::default()
    };
    config.peers = peers;
    let policy = match policy {
        None => None,
        Some("voi") => Some(SendPolicy::Voi),
        Some("baseline") => Some(SendPolicy::Baseline),
        Some("every") => Some(SendPolicy::Every),
        Some(other) => {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                format!("team_policy {other:?} is not \"voi\", \"baseline\" or \"every\""),
            ))
        }
    };
    let team = (cfg.no_team_layer == 0).then(|| {
        let mut team = TeamLayerConfig::new(usize::from(team_size), budget_interval);
        if let Some(policy) = policy {
            team.team.send_policy = policy;
        }
        team
    });
    // As `huddle daemon`'s `gamecontroller_config`.
    let asked = match cfg.gamecontroller {
        HUDDLE_GC_AUTO => budget == Some(BudgetSpec::SPL),
        HUDDLE_GC_ON => true,
        HUDDLE_GC_OFF => false,
        other => {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                format!("gamecontroller {other} is not HUDDLE_GC_AUTO, _ON or _OFF"),
            ))
        }
    };
    let gc = if asked {
        let mut gc = GameControllerConfig::new(cfg.team_id, robot_id);
        if let Some(listen) = gc_listen {
            gc.listen = listen.parse().map_err(|_| {
                Failure::new(
                    HUDDLE_E_NETWORK,
                    format!("gc_listen {listen:?} is not ADDR:PORT"),
                )
            })?;
        }
        if cfg.gc_status_port != 0 {
            gc.status_port = cfg.gc_status_port;
        }
        if let Some(spec) = budget {
            let mut b = gamecontroller::GcBudget::spl(team_size);
            b.messages_per_game = u32::try_from(spec.team_messages).unwrap_or(u32::MAX);
            b.half = spec.game / 2;
            gc.budget = Some(b);
        }
        Some((gc, cfg.gamecontroller == HUDDLE_GC_ON))
    } else {
        None
    };
    Ok(NodeConfig {
        driver: config,
        team,
        gc,
    })
}

/// The caller's `peers`, each `ADDR:PORT`.
///
/// # Safety
///
/// `peers` is NULL (then `count` is 0) or points to `count` NULL or NUL-terminated
/// strings.
unsafe fn read_peers(
    peers: *const *const c_char,
    count: usize,
) -> Result<Vec<std::net::SocketAddr>, Failure> {
    if count == 0 {
        return Ok(Vec::new());
    }
    if peers.is_null() {
        return Err(Failure::null("peers"));
    }
    // SAFETY: non-NULL, and the caller promises `count` pointers.
    let list = unsafe { std::slice::from_raw_parts(peers, count) };
    list.iter()
        .enumerate()
        .map(|(i, &p)| {
            // SAFETY: the caller promises NULL or NUL-terminated strings.
            let text = unsafe { read_str(p, &format!("peers[{i}]")) }?;
            text.parse().map_err(|_| {
                Failure::new(
                    HUDDLE_E_NETWORK,
                    format!("peers[{i}] {text:?} is not ADDR:PORT"),
                )
            })
        })
        .collect()
}

/// The key a read found: `*.var.x` reads the owner's copy `n.var.x`.
fn stored_key(asked: &Key, entry: &Entry) -> Key {
    match asked.scope() {
        comms::Scope::Global => asked.with_scope(comms::Scope::Robot(entry.owner)),
        _ => asked.clone(),
    }
}

/// The live node behind `node`.
pub(crate) fn lookup(node: *const huddle_node) -> Result<Arc<Node>, Failure> {
    if node.is_null() {
        return Err(Failure::null("node"));
    }
    NODES.get(node).ok_or_else(|| Failure::stopped("node"))
}

/// Sets `key` to `value` on the caller's thread (see `huddle_node_set`); `priority`: the
/// priority path (`Replica::set_priority`).
pub(crate) fn set_value(
    node: *mut huddle_node,
    key: &str,
    value: Value,
    priority: bool,
) -> Result<(), Failure> {
    let node = lookup(node)?;
    let key = Key::parse(key).map_err(|e| Failure::new(HUDDLE_E_KEY, e.to_string()))?;
    node.with_state(|state, now| {
        state.set(now, &key.to_string(), value, |replica, value| {
            if priority {
                replica.set_priority(now, &key, value)
            } else {
                replica.set_key(now, &key, value)
            }
            .map_err(set_failure)
        })
    })?
}

/// The value at `key` (as `huddle_node_get` reads it), if there is one.
pub(crate) fn get_value(node: *mut huddle_node, key: &str) -> Result<Option<Value>, Failure> {
    let node = lookup(node)?;
    node.with_state(|state, _| state.replica.get(key).map(|e| e.map(|e| e.value.clone())))?
        .map_err(|e| Failure::new(HUDDLE_E_KEY, e.to_string()))
}

fn parse_value(literal: &str) -> Result<Value, Failure> {
    comms::parse_literal(literal)
        .map_err(|e| Failure::new(HUDDLE_E_LITERAL, format!("value {literal:?}: {e}")))
}

pub(crate) fn set_failure(e: SetError) -> Failure {
    Failure::new(HUDDLE_E_KEY, e.to_string())
}

pub(crate) fn post_failure(e: PostError) -> Failure {
    let code = match e {
        PostError::Key(_) | PostError::NotOwnQueue(_) => HUDDLE_E_KEY,
        _ => HUDDLE_E_POST,
    };
    Failure::new(code, e.to_string())
}

/// Starts a node: opens the team's multicast socket on the interface, applies the
/// config files, sends the first frame, and receives (and runs the replica's timers) on a
/// thread of its own until `huddle_node_stop`.
/// With `id_check_ms`, it first listens that long for another robot with its id.
/// Returns NULL on failure, with the reason in `err` (bad robot id, transport, group,
/// interface, peer, budget, key file, config directory or config line; the port or
/// group could not be joined; `HUDDLE_E_ID_CONFLICT`: another robot sends with this id).
///
/// Thread safety: may be called from any thread.
///
/// # Safety
///
/// `cfg` is NULL or points to a valid `huddle_node_config` whose strings are NULL or
/// NUL-terminated; `err` is NULL or points to a writable `huddle_error`.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_start(
    cfg: *const huddle_node_config,
    err: *mut huddle_error,
) -> *mut huddle_node {
    let body = || {
        // SAFETY: the caller promises `cfg` is NULL or valid for reads.
        let cfg = unsafe { cfg.as_ref() }.ok_or_else(|| Failure::null("cfg"))?;
        let config = driver_config(cfg)?;
        let node = Engine::start(config.driver, config.team)?;
        if let Some((gc, required)) = config.gc {
            let listen = gc.listen;
            match node.start_gc(gc) {
                Ok(()) => {}
                Err(e) if required => {
                    node.stop();
                    return Err(e);
                }
                // On by default with the SPL budget: run as before, loudly (the C caller
                // has no log: stderr is all there is).
                Err(e) => eprintln!(
                    "huddle node: CANNOT LISTEN FOR THE GAMECONTROLLER on {listen}: the budget \
                     is paced from the node's start and cannot see the team's count ({})",
                    e.message
                ),
            }
        }
        if cfg.id_check_ms > 0 {
            // The I/O shell waits on the caller's thread, as it asked (not the sans-IO core).
            #[allow(clippy::disallowed_methods)]
            std::thread::sleep(Duration::from_millis(cfg.id_check_ms.into()));
            let (robot, conflicts) = node.with_state(|state, _| {
                (state.replica.robot_id(), state.replica.stats().id_conflicts)
            })?;
            if conflicts > 0 {
                node.stop();
                return Err(Failure::new(
                    HUDDLE_E_ID_CONFLICT,
                    format!(
                        "another robot is sending with robot id {robot}: not started \
                         (two programs with one id would overwrite each other's values)"
                    ),
                ));
            }
        }
        Ok(NODES.insert(Arc::new(node)))
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, std::ptr::null_mut(), body) }
}

/// Sets `key` (`*.var.x`: published to the team; `local.var.x`: this robot only) to the
/// value the `literal` spells (`42`, `1.5`, `true`, `"text"`, `[1, 2.5]`, `0x0a0b`).
/// A global value is on the wire when this returns. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` and `literal` are NULL or NUL-terminated strings; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set(
    node: *mut huddle_node,
    key: *const c_char,
    literal: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises NULL or NUL-terminated strings.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: as above.
        let value = parse_value(unsafe { read_str(literal, "literal") }?)?;
        node.with_state(|state, now| {
            state.set(now, key, value, |replica, value| {
                replica.set(now, key, value).map_err(set_failure)
            })
        })??;
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Reads `key` (`2.var.x`: robot 2's copy; `*.var.x`: the newest copy of any robot;
/// `local.var.x`) into `out`: key as stored, type, value as a literal, owner, age in ms.
/// Returns 1 when found, 0 when the key is unknown (`out` untouched), -1 on error.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or points to a writable
/// `huddle_binding`; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get(
    node: *mut huddle_node,
    key: *const c_char,
    out: *mut huddle_binding,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        let found = node
            .with_state(|state, now| {
                let parsed = Key::parse(key)?;
                Ok::<_, comms::KeyError>(
                    state
                        .replica
                        .get(key)?
                        .map(|entry| (stored_key(&parsed, entry), entry.clone(), entry.age(now))),
                )
            })?
            .map_err(|e| Failure::new(HUDDLE_E_KEY, e.to_string()))?;
        Ok(match found {
            Some((key, entry, age)) => {
                fill_binding(out, &key, &entry, age);
                1
            }
            None => 0,
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Posts the value `literal` spells to this robot's talk queue `key` (`*.talk.plan`):
/// every teammate gets it once, in order, as `HUDDLE_EVENT_TALK_DELIVERED` (or learns
/// it was lost: `HUDDLE_EVENT_TALK_GIVEN_UP`). Writes its sequence number to `seq` when
/// not NULL. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` and `literal` are NULL or NUL-terminated; `seq` is NULL or writable; `err` is
/// NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_post(
    node: *mut huddle_node,
    key: *const c_char,
    literal: *const c_char,
    seq: *mut u64,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises NULL or NUL-terminated strings.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: as above.
        let value = parse_value(unsafe { read_str(literal, "literal") }?)?;
        let n = node
            .with_state(|state, now| state.replica.post(now, key, value))?
            .map_err(post_failure)?;
        // SAFETY: the caller promises `seq` is NULL or valid for writes.
        if let Some(seq) = unsafe { seq.as_mut() } {
            *seq = n;
        }
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Takes the next event (talk delivered or given up, peer joined, departed or
/// restarted, events dropped) into `out`, waiting up to `timeout_ms` for one (0: do not
/// wait). Returns 1 with an event, 0 when there was none, -1 on error. Events wait in a
/// queue of 65,536; beyond that the oldest are dropped and `HUDDLE_EVENT_LAGGED` says
/// how many. Events queued before `huddle_node_stop` can no longer be read after it.
///
/// Thread safety: may be called from any thread; several threads polling share one
/// queue (each event goes to one of them).
///
/// # Safety
///
/// `out` is NULL or points to a writable `huddle_event`; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_next_event(
    node: *mut huddle_node,
    timeout_ms: u32,
    out: *mut huddle_event,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        Ok(
            match node
                .shared
                .events
                .pop(Duration::from_millis(timeout_ms.into()))
            {
                Some(event) => {
                    fill_node_event(out, &event);
                    1
                }
                None => 0,
            },
        )
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Stops the node (its thread ends, its socket closes) and releases it; takes up to
/// 20 ms (the longest its receive thread waits before it looks for a stop). The pointer is
/// dead afterwards: any call with it returns -1 with `HUDDLE_E_STOPPED`, a second stop
/// does nothing. NULL does nothing.
///
/// Thread safety: may be called from any thread; calls still running on other threads
/// finish first or return `HUDDLE_E_STOPPED`.
#[no_mangle]
pub extern "C" fn huddle_node_stop(node: *mut huddle_node) {
    let _ = std::panic::catch_unwind(|| {
        if let Some(node) = NODES.remove(node) {
            node.stop();
        }
    });
}
