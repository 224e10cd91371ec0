//! Talking to a daemon's relay from the command line: where it is (`--relay`, with
//! `HUDDLE_RELAY` as the default), a blocking line-protocol connection, and bindings as
//! JSON.

use std::fmt;
use std::io::{BufRead, BufReader, Write};
use std::net::{IpAddr, SocketAddr, TcpStream, ToSocketAddrs};
use std::str::FromStr;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use comms::relay::Binding;
use serde_json::json;

/// The relay's port when only a host is given.
pub const DEFAULT_PORT: u16 = 2001;

/// Where a relay is, as typed: `host:port`, a bare port (on 127.0.0.1), or a host name
/// or address (on port 2001). Names are resolved when connecting or binding.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RelayTarget {
    /// Host name or IP address.
    pub host: String,
    /// TCP port.
    pub port: u16,
}

impl FromStr for RelayTarget {
    type Err = String;

    fn from_str(s: &str) -> Result<RelayTarget, String> {
        let s = s.trim();
        let target = |host: &str, port: u16| RelayTarget {
            host: host
                .trim_start_matches('[')
                .trim_end_matches(']')
                .to_owned(),
            port,
        };
        if let Ok(port) = s.parse::<u16>() {
            return Ok(target("127.0.0.1", port));
        }
        if let Ok(addr) = s.parse::<SocketAddr>() {
            return Ok(target(&addr.ip().to_string(), addr.port()));
        }
        if let Ok(ip) = s.parse::<IpAddr>() {
            return Ok(target(&ip.to_string(), DEFAULT_PORT));
        }
        let (host, port) = match s.rsplit_once(':') {
            Some((host, port)) => {
                let port = port
                    .parse::<u16>()
                    .map_err(|_| format!("{s:?}: the port {port:?} is not a number 0..=65535"))?;
                (host, port)
            }
            None => (s, DEFAULT_PORT),
        };
        let name_ok = !host.is_empty()
            && !host.bytes().all(|b| b.is_ascii_digit() || b == b'.')
            && host.len() <= 253
            && host
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'-' | b'.' | b'_'));
        if !name_ok {
            return Err(format!(
                "{s:?} is not a relay address: give host:port (localhost:2001), a port (2001) \
                 or a host name (robot3)"
            ));
        }
        Ok(target(host, port))
    }
}

impl fmt::Display for RelayTarget {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.host.contains(':') {
            write!(f, "[{}]:{}", self.host, self.port)
        } else {
            write!(f, "{}:{}", self.host, self.port)
        }
    }
}

impl RelayTarget {
    /// The addresses the host resolves to, with the port.
    pub fn resolve(&self) -> Result<Vec<SocketAddr>> {
        let addrs: Vec<SocketAddr> = (self.host.as_str(), self.port)
            .to_socket_addrs()
            .with_context(|| format!("cannot resolve the relay host {:?}", self.host))?
            .collect();
        if addrs.is_empty() {
            bail!("the relay host {:?} has no address", self.host);
        }
        Ok(addrs)
    }
}

/// Where the daemon's relay listens (clients' `--relay`).
#[derive(Args, Debug, Clone)]
pub struct RelayAddr {
    /// The daemon's relay: host:port, a port (on 127.0.0.1) or a host name (port 2001).
    #[arg(long, env = "HUDDLE_RELAY", default_value = "127.0.0.1:2001")]
    pub relay: RelayTarget,
}

/// A blocking relay connection.
pub struct RelayClient {
    reader: BufReader<TcpStream>,
    writer: TcpStream,
    /// The greeting line.
    pub greeting: String,
}

impl RelayClient {
    /// Connects (to the first address of the target that answers) and reads the greeting.
    pub fn connect(target: &RelayTarget) -> Result<RelayClient> {
        let mut last = None;
        for addr in target.resolve()? {
            match TcpStream::connect_timeout(&addr, Duration::from_secs(2)) {
                Ok(stream) => return RelayClient::over(stream, target),
                Err(e) => last = Some(e),
            }
        }
        let e = last.map_or_else(|| "no address".to_owned(), |e| e.to_string());
        bail!("cannot reach a huddle relay at {target}: {e} (is the daemon running?)")
    }

    /// Connects to one socket address.
    pub fn connect_addr(addr: SocketAddr) -> Result<RelayClient> {
        let target = RelayTarget {
            host: addr.ip().to_string(),
            port: addr.port(),
        };
        RelayClient::connect(&target)
    }

    fn over(stream: TcpStream, target: &RelayTarget) -> Result<RelayClient> {
        stream.set_nodelay(true)?;
        let writer = stream.try_clone()?;
        let mut client = RelayClient {
            reader: BufReader::new(stream),
            writer,
            greeting: String::new(),
        };
        client.greeting = client.line()?;
        if client.greeting.starts_with("ERR ") {
            // A relay that refuses the connection (`ERR 503`: as many clients as its
            // `--max-clients` are connected) says why instead of greeting.
            bail!(
                "the relay at {target} refused the connection: {}",
                client.greeting
            );
        }
        if !client.greeting.starts_with("HUDDLE ") {
            bail!(
                "{target} is not a huddle relay (it said {:?})",
                client.greeting
            );
        }
        Ok(client)
    }

    /// The relay's robot id, from its greeting.
    pub fn robot(&self) -> Option<u8> {
        greeting_robot(&self.greeting)
    }

    /// Sends one command line.
    pub fn send(&mut self, line: &str) -> Result<()> {
        self.writer.write_all(line.as_bytes())?;
        self.writer.write_all(b"\n")?;
        Ok(())
    }

    /// Reads one line, without its terminator.
    pub fn line(&mut self) -> Result<String> {
        let mut s = String::new();
        if self.reader.read_line(&mut s)? == 0 {
            bail!("the relay closed the connection");
        }
        Ok(s.trim_end_matches(['\r', '\n']).to_owned())
    }

    /// Sends a command and reads its one-line answer; `ERR` becomes an error.
    pub fn request(&mut self, line: &str) -> Result<String> {
        self.send(line)?;
        let answer = self.line()?;
        match answer.strip_prefix("ERR ") {
            Some(err) => Err(anyhow!("relay refused {line:?}: {err}")),
            None => Ok(answer),
        }
    }

    /// `GETV key`: the binding, or `None` when no value is bound (`ERR 404`).
    /// With a maximum age, an older value is an error (`ERR 406`) naming its age, not an
    /// answer.
    pub fn get(&mut self, key: &str, max_age: Option<Duration>) -> Result<Option<Binding>> {
        match max_age {
            Some(age) => self.send(&format!("GETV {key} {}", age.as_millis()))?,
            None => self.send(&format!("GETV {key}"))?,
        }
        let answer = self.line()?;
        if answer.starts_with("ERR 404 ") {
            return Ok(None);
        }
        if let Some(err) = answer.strip_prefix("ERR ") {
            bail!("relay refused GETV {key}: {err}");
        }
        Binding::parse(&answer)
            .map(Some)
            .ok_or_else(|| anyhow!("unexpected answer {answer:?}"))
    }

    /// Reads lines until the `stop` line, returning those before it.
    pub fn lines_until(&mut self, stop: &str) -> Result<Vec<String>> {
        let mut out = Vec::new();
        loop {
            let line = self.line()?;
            if line == stop {
                return Ok(out);
            }
            out.push(line);
        }
    }

    /// Every binding matching `pattern` right now, in key order (a watch, one push, `QUIT`).
    pub fn snapshot(&mut self, patterns: &[&str]) -> Result<Vec<Binding>> {
        for p in patterns {
            self.request(&format!("ADDW {p}"))?;
        }
        // REFR pushes the current state at once; QUIT's BYE marks its end.
        self.send("REFR 3600000")?;
        self.send("QUIT")?;
        let lines = self.lines_until("BYE")?;
        Ok(lines.iter().filter_map(|l| Binding::parse(l)).collect())
    }

    /// The reading half, for a thread that only reads pushes.
    pub fn into_reader(self) -> BufReader<TcpStream> {
        self.reader
    }
}

/// A value literal as JSON (the monitor's form, shared with `huddle get --json`).
pub use monitor::value_json;

/// The robot a binding belongs to, as a number: the key's first level (`3.var.x` -> 3),
/// or for a `local.` key the relay's own robot (`robot`, from its greeting).
pub fn owner_id(b: &Binding, robot: Option<u8>) -> Option<u8> {
    b.owner().parse::<u8>().ok().or(robot)
}

/// The robot id in a relay greeting (`HUDDLE 2 robot 3` -> 3).
pub fn greeting_robot(greeting: &str) -> Option<u8> {
    match greeting.split_whitespace().collect::<Vec<_>>()[..] {
        ["HUDDLE", _, "robot", id] => id.parse().ok(),
        _ => None,
    }
}

/// A binding as one JSON object: key, owner (an integer, as in `/state` and Python; for
/// a `local.` key the relay's robot `robot`), type, value, age_ms, departed.
pub fn binding_json(b: &Binding, robot: Option<u8>) -> serde_json::Value {
    json!({
        "key": b.key,
        "owner": owner_id(b, robot),
        "type": b.ty,
        "value": value_json(&b.value),
        "age_ms": b.age_ms,
        "departed": b.departed,
    })
}

/// The wall-clock time now as RFC 3339 UTC with milliseconds (`2025-11-24T09:41:07.123Z`).
pub fn utc_now() -> String {
    let since = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default();
    let secs = since.as_secs();
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Howard Hinnant's civil_from_days.
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:03}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60,
        since.subsec_millis()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(s: &str) -> Result<String, String> {
        s.parse::<RelayTarget>().map(|t| t.to_string())
    }

    #[test]
    fn relay_takes_host_port_a_bare_port_or_a_host_name() {
        assert_eq!(t("127.0.0.1:2001").as_deref(), Ok("127.0.0.1:2001"));
        assert_eq!(t("localhost:2001").as_deref(), Ok("localhost:2001"));
        assert_eq!(t("2002").as_deref(), Ok("127.0.0.1:2002"));
        assert_eq!(t("robot3").as_deref(), Ok("robot3:2001"));
        assert_eq!(t("robot3.lan:7").as_deref(), Ok("robot3.lan:7"));
        assert_eq!(t("10.0.0.3").as_deref(), Ok("10.0.0.3:2001"));
        assert_eq!(t("[::1]:2003").as_deref(), Ok("[::1]:2003"));
        assert_eq!(t("::1").as_deref(), Ok("[::1]:2001"));
        assert!(t("localhost:http").is_err());
        assert!(t("robot 3").is_err());
        assert!(t("").is_err());
        assert!(t("99999").is_err());
    }

    #[test]
    fn values_become_json_of_their_type() {
        assert_eq!(value_json("42"), json!(42));
        assert_eq!(value_json("1.5"), json!(1.5));
        assert_eq!(value_json("NaN"), json!("NaN"));
        assert_eq!(value_json("true"), json!(true));
        assert_eq!(value_json("\"a \\\"b\\\"\""), json!("a \"b\""));
        assert_eq!(value_json("[1.5, -2.0]"), json!([1.5, -2.0]));
        assert_eq!(value_json("0x0a0b"), json!("0x0a0b"));
    }

    #[test]
    fn utc_time_has_the_rfc3339_shape() {
        let now = utc_now();
        assert_eq!(now.len(), 24, "{now}");
        assert!(now.starts_with("20") && now.ends_with('Z'), "{now}");
        assert_eq!(&now[10..11], "T");
    }
}
