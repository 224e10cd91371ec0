//! The keys a team layer reads and writes at every tick, built once (moved out of
//! `layer.rs` to keep it short).

use comms::{Key, Scope};

use super::{pass_to_key, robot_id, world_local_key, world_local_of};

/// The keys a [`TeamLayer`](super::TeamLayer) uses at every tick, built once.
#[derive(Debug, Clone)]
pub(super) struct LayerKeys {
    /// [`WORLD_LOCAL_KEY`](super::WORLD_LOCAL_KEY), its own.
    pub(super) world_local: Key,
    /// [`PASS_TO_KEY`](super::PASS_TO_KEY), its own.
    pub(super) pass_to: Key,
    /// Per robot (index = id − 1): where its LWM is held.
    pub(super) world_local_of: Vec<Key>,
    /// Per robot (index = id − 1): where its pass receiver is held.
    pub(super) pass_to_of: Vec<Key>,
}

impl LayerKeys {
    pub(super) fn new(team: usize) -> Self {
        let pass_to = pass_to_key();
        LayerKeys {
            world_local: world_local_key(),
            world_local_of: (0..team).map(|k| world_local_of(robot_id(k))).collect(),
            pass_to_of: (0..team)
                .map(|k| pass_to_of(robot_id(k), &pass_to).expect("a valid key"))
                .collect(),
            pass_to,
        }
    }

    /// Where robot `id`'s pass receiver is held (`None`: not a valid robot id).
    pub(super) fn pass_to_of(&self, id: u8) -> Option<Key> {
        match usize::from(id)
            .checked_sub(1)
            .and_then(|k| self.pass_to_of.get(k))
        {
            Some(key) => Some(key.clone()),
            None => pass_to_of(id, &self.pass_to).ok(),
        }
    }
}

/// Robot `id`'s binding of the pass receiver key `pass_to`.
fn pass_to_of(id: u8, pass_to: &Key) -> Result<Key, comms::KeyError> {
    Key::new(Scope::Robot(id), comms::Kind::Var, pass_to.path())
}
