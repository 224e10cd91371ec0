//! huddle keys as Zenoh key expressions, and back.
//!
//! ```text
//! huddle/@v1/<venue>/<team>/<robot>/var/<path, one chunk per level>   a value
//! huddle/@v1/<venue>/<team>/<robot>/talk/<queue>                      a talk message
//! huddle/@v1/<venue>/<team>/<robot>/@alive/<incarnation, 16 hex>      liveliness
//! huddle/@v1/<venue>/<team>/@bridge/stats | @bridge/peers             the bridge
//! ```
//!
//! `@v1`, `@alive` and `@bridge` are verbatim chunks: `**` never matches them, so a
//! subscriber on `huddle/@v1/<venue>/7/**` gets the team's values and nothing of the
//! bridge's own keys, and an ACL on `huddle/@v1/<venue>/7/**` covers the values.

use std::fmt::Write;

use thiserror::Error;

/// The version chunk: a breaking change to the mapping bumps it.
pub const VERSION_CHUNK: &str = "@v1";

/// A name that cannot be one chunk of a key expression.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum ChunkError {
    /// Empty.
    #[error("{what} is empty")]
    Empty {
        /// What was checked (`--venue`).
        what: &'static str,
    },
    /// A character outside `[A-Za-z0-9_-]`.
    #[error("{what} {name:?} has {ch:?}: only letters, digits, '-' and '_' are allowed")]
    BadChar {
        /// What was checked.
        what: &'static str,
        /// The name.
        name: String,
        /// The first character refused.
        ch: char,
    },
}

/// Checks that `name` can be one chunk. Stricter than Zenoh (which only refuses
/// `/*$?#@` and empty chunks): a venue name also has to be a ROS 2 name part.
pub fn check_chunk(what: &'static str, name: &str) -> Result<(), ChunkError> {
    if name.is_empty() {
        return Err(ChunkError::Empty { what });
    }
    match name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        Some(ch) => Err(ChunkError::BadChar {
            what,
            name: name.to_owned(),
            ch,
        }),
        None => Ok(()),
    }
}

/// The key expressions of one team at one venue.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TeamKeys {
    /// `huddle/@v1/<venue>/<team>`.
    prefix: String,
    /// `<ros prefix>/<venue>/team<team>`, for `--ros2`.
    ros_prefix: String,
}

/// A huddle path that has no key expression (cannot happen for a path the replica
/// accepted, whose levels are `[A-Za-z0-9_-]+`, but checked rather than assumed).
#[derive(Debug, Error, PartialEq, Eq)]
#[error("path {0:?} cannot map to a key expression")]
pub struct Unmappable(pub String);

impl TeamKeys {
    /// Keys for `team` at `venue` (checked with [`check_chunk`]). `ros_root`: the first
    /// chunk of `--ros2` keys (`huddle_ros` by default).
    pub fn new(venue: &str, team: u8, ros_root: &str) -> Result<TeamKeys, ChunkError> {
        check_chunk("--venue", venue)?;
        check_chunk("--ros2-prefix", ros_root)?;
        Ok(TeamKeys {
            prefix: format!("huddle/{VERSION_CHUNK}/{venue}/{team}"),
            ros_prefix: format!("{ros_root}/{venue}/team{team}"),
        })
    }

    /// `huddle/@v1/<venue>/<team>`.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// `huddle/@v1/<venue>/<team>/**`: every value and talk key of the team.
    pub fn all(&self) -> String {
        format!("{}/**", self.prefix)
    }

    /// The value key of `robot`'s `path` (`ball.dist` → `…/2/var/ball/dist`).
    pub fn var(&self, robot: u8, path: &str) -> Result<String, Unmappable> {
        self.under(robot, "var", path)
    }

    /// The key of `robot`'s talk queue `queue`.
    pub fn talk(&self, robot: u8, queue: &str) -> Result<String, Unmappable> {
        self.under(robot, "talk", queue)
    }

    fn under(&self, robot: u8, kind: &str, path: &str) -> Result<String, Unmappable> {
        if comms::validate_path(path).is_err() {
            return Err(Unmappable(path.to_owned()));
        }
        let mut key = String::with_capacity(self.prefix.len() + path.len() + 10);
        key.push_str(&self.prefix);
        key.push('/');
        // Writing to a String cannot fail.
        let _ = write!(key, "{robot}/{kind}/");
        for c in path.chars() {
            key.push(if c == '.' { '/' } else { c });
        }
        Ok(key)
    }

    /// The liveliness token of `robot` in its life `incarnation`.
    pub fn alive(&self, robot: u8, incarnation: u64) -> String {
        format!("{}/{robot}/@alive/{incarnation:016x}", self.prefix)
    }

    /// Every liveliness token of the team (`…/*/@alive/*`).
    pub fn alive_all(&self) -> String {
        format!("{}/*/@alive/*", self.prefix)
    }

    /// `…/@bridge/stats` or `…/@bridge/peers`.
    pub fn bridge(&self, what: &str) -> String {
        format!("{}/@bridge/{what}", self.prefix)
    }

    /// The `--ros2` key of `robot`'s `path`: `<root>/<venue>/team7/robot2/ball/dist`,
    /// the ROS 2 topic `/<root>/<venue>/team7/robot2/ball/dist` once zenoh-bridge-ros2dds
    /// routes it. ROS 2 names allow `[A-Za-z0-9_]` and no level starting with a digit:
    /// a path with `-` or such a level has no topic (`Unmappable`), rather than one that
    /// could collide with another path's.
    pub fn ros2(&self, robot: u8, path: &str) -> Result<String, Unmappable> {
        let ok = path.split('.').all(|level| {
            !level.is_empty()
                && !level.starts_with(|c: char| c.is_ascii_digit())
                && level.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        });
        if !ok {
            return Err(Unmappable(path.to_owned()));
        }
        Ok(format!(
            "{}/robot{robot}/{}",
            self.ros_prefix,
            path.replace('.', "/")
        ))
    }

    /// Parses a value key back: `(robot, path)`. `None` for any other key.
    pub fn parse_var(&self, key: &str) -> Option<(u8, String)> {
        let rest = key.strip_prefix(&self.prefix)?.strip_prefix('/')?;
        let (robot, rest) = rest.split_once('/')?;
        let path = rest.strip_prefix("var/")?.replace('/', ".");
        comms::validate_path(&path).ok()?;
        Some((robot.parse().ok()?, path))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys() -> TeamKeys {
        TeamKeys::new("robocup-2026", 7, "huddle_ros").unwrap()
    }

    #[test]
    fn a_value_key_has_one_chunk_per_level() {
        let k = keys();
        assert_eq!(
            k.var(2, "ball.dist").unwrap(),
            "huddle/@v1/robocup-2026/7/2/var/ball/dist"
        );
        assert_eq!(
            k.var(254, "machine.config.def.near-ball").unwrap(),
            "huddle/@v1/robocup-2026/7/254/var/machine/config/def/near-ball"
        );
        assert_eq!(
            k.talk(10, "plan").unwrap(),
            "huddle/@v1/robocup-2026/7/10/talk/plan"
        );
        assert_eq!(
            k.parse_var("huddle/@v1/robocup-2026/7/2/var/ball/dist"),
            Some((2, "ball.dist".into())),
            "the mapping goes back"
        );
        assert_eq!(
            k.parse_var("huddle/@v1/robocup-2026/8/2/var/ball/dist"),
            None
        );
    }

    #[test]
    fn liveliness_and_bridge_keys() {
        let k = keys();
        assert_eq!(
            k.alive(3, 0xdead_beef),
            "huddle/@v1/robocup-2026/7/3/@alive/00000000deadbeef"
        );
        assert_eq!(k.bridge("stats"), "huddle/@v1/robocup-2026/7/@bridge/stats");
        assert_eq!(k.all(), "huddle/@v1/robocup-2026/7/**");
    }

    #[test]
    fn paths_that_cannot_map_are_refused_not_mangled() {
        let k = keys();
        assert_eq!(k.var(1, "a..b"), Err(Unmappable("a..b".into())));
        assert_eq!(k.var(1, "a/b"), Err(Unmappable("a/b".into())));
        assert_eq!(k.var(1, "**"), Err(Unmappable("**".into())));
        assert!(k.ros2(1, "near-ball").is_err(), "'-' is not in ROS 2 names");
        assert!(
            k.ros2(1, "pose.0").is_err(),
            "a ROS 2 level cannot start with a digit"
        );
        assert_eq!(
            k.ros2(2, "ball.dist").unwrap(),
            "huddle_ros/robocup-2026/team7/robot2/ball/dist"
        );
    }

    #[test]
    fn venue_names_are_checked() {
        assert!(TeamKeys::new("", 1, "r").is_err());
        assert!(TeamKeys::new("a/b", 1, "r").is_err());
        assert!(TeamKeys::new("**", 1, "r").is_err());
        assert!(TeamKeys::new("@x", 1, "r").is_err());
        assert!(TeamKeys::new("lab_2", 1, "r").is_ok());
    }

    proptest::proptest! {
        /// Every path the replica accepts maps to a key that maps back to it.
        #[test]
        fn any_valid_path_round_trips(levels in proptest::collection::vec("[A-Za-z0-9_-]{1,8}", 1..6), robot in 1u8..=254) {
            let path = levels.join(".");
            let k = keys();
            let key = k.var(robot, &path).unwrap();
            proptest::prop_assert_eq!(k.parse_var(&key), Some((robot, path)));
        }

        /// Arbitrary text never panics the parsers.
        #[test]
        fn garbage_keys_parse_to_none_or_a_valid_path(s in ".{0,80}") {
            if let Some((_, path)) = keys().parse_var(&s) {
                proptest::prop_assert!(comms::validate_path(&path).is_ok());
            }
            let _ = crate::export::parse_attachment(&s);
        }
    }
}
