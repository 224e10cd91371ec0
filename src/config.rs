//! [`Config`] and [`open`]: a robot's place on the team's network, and the session on it.

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

use comms::{Key, ReplicaConfig, Value};
use driver::{DriverConfig, DriverError, Session, Transport};

/// Who this robot is and where its team talks: a [`DriverConfig`] with a builder in
/// front. The defaults are the seed's: multicast to `224.0.0.1:2000` on the loopback
/// interface (nothing leaves the machine until [`Config::iface`] names a real one).
#[derive(Clone, Debug)]
pub struct Config {
    /// Everything, for what the builder does not cover (refresh period, MTU, team key,
    /// talk limits, budget).
    pub driver: DriverConfig,
}

impl Config {
    /// Robot `robot_id` (1..=254) of team `team_id`.
    pub fn new(robot_id: u8, team_id: u8) -> Config {
        Config {
            driver: DriverConfig::new(ReplicaConfig::new(robot_id, team_id)),
        }
    }

    /// The multicast group and port (with broadcast or unicast, the port).
    #[must_use]
    pub fn group(mut self, group: SocketAddrV4) -> Config {
        self.driver.socket.group = group;
        self
    }

    /// The interface's IPv4 address the team's frames leave from and arrive on.
    #[must_use]
    pub fn iface(mut self, iface: Ipv4Addr) -> Config {
        self.driver.socket.iface = iface;
        self
    }

    /// Multicast (the default), broadcast (RoboCup SPL) or unicast to the peers only.
    #[must_use]
    pub fn transport(mut self, transport: Transport) -> Config {
        self.driver.socket.transport = transport;
        self
    }

    /// A teammate that also gets every frame by unicast (with [`Transport::Unicast`],
    /// the only destinations).
    #[must_use]
    pub fn peer(mut self, peer: SocketAddr) -> Config {
        self.driver.peers.push(peer);
        self
    }

    /// A value bound before the first frame goes out.
    #[must_use]
    pub fn start_value(mut self, key: Key, value: impl Into<Value>) -> Config {
        self.driver.start_values.push((key, value.into()));
        self
    }
}

impl From<DriverConfig> for Config {
    fn from(driver: DriverConfig) -> Config {
        Config { driver }
    }
}

/// Joins the team: opens the socket, starts this robot's replica and its receive task on
/// the current tokio runtime (multi-threaded or not), and returns the session, a
/// `Send + Sync + Clone` handle for any task.
pub async fn open(config: impl Into<Config>) -> Result<Session, DriverError> {
    Session::open(config.into().driver).await
}
