//! The command-line clients: `huddle get`, `set`, `watch` (the seed's Monitor) and
//! `stats`. Each speaks the relay line protocol to a daemon (`--relay ADDR:PORT`).

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, IsTerminal, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use comms::relay::Binding;

/// Where the daemon's relay listens.
#[derive(Args, Debug, Clone)]
pub struct RelayAddr {
    /// The daemon's relay address.
    #[arg(long, default_value = "127.0.0.1:2001")]
    pub relay: SocketAddr,
}

/// `huddle get KEY`
#[derive(Args, Debug)]
pub struct GetArgs {
    /// Key: `*.var.x` (newest copy of any robot), `3.var.x`, `local.var.x`.
    pub key: String,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// `huddle set KEY VALUE`
#[derive(Args, Debug)]
pub struct SetArgs {
    /// Key: `*.var.x`, `local.var.x`; `*.talk.q` posts a message.
    pub key: String,
    /// Value literal: `42`, `4.2`, `true`, `'"text"'`, `'[1, 2]'`, `0x0a0b` (several
    /// words are joined by spaces).
    #[arg(required = true, num_args = 1.., allow_negative_numbers = true)]
    pub value: Vec<String>,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// `huddle watch PATTERN...`
#[derive(Args, Debug)]
pub struct WatchArgs {
    /// Patterns: `+` one level, `#` the rest (`+.var.machine.#`, `2.var.#`).
    #[arg(required = true)]
    pub patterns: Vec<String>,
    /// Refresh interval in milliseconds.
    #[arg(long, default_value_t = 500)]
    pub interval: u64,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// `huddle stats`
#[derive(Args, Debug)]
pub struct StatsArgs {
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// A blocking relay connection.
pub struct RelayClient {
    reader: BufReader<TcpStream>,
    writer: TcpStream,
    /// The greeting line.
    pub greeting: String,
}

impl RelayClient {
    /// Connects and reads the greeting.
    pub fn connect(addr: SocketAddr) -> Result<RelayClient> {
        let stream =
            TcpStream::connect_timeout(&addr, Duration::from_secs(2)).with_context(|| {
                format!("cannot reach a huddle relay at {addr} (is the daemon running?)")
            })?;
        stream.set_nodelay(true)?;
        let writer = stream.try_clone()?;
        let mut client = RelayClient {
            reader: BufReader::new(stream),
            writer,
            greeting: String::new(),
        };
        client.greeting = client.line()?;
        if !client.greeting.starts_with("HUDDLE ") {
            bail!(
                "{addr} is not a huddle relay (it said {:?})",
                client.greeting
            );
        }
        Ok(client)
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

    fn into_reader(self) -> BufReader<TcpStream> {
        self.reader
    }
}

/// `huddle get`
pub fn get(args: GetArgs) -> Result<()> {
    let mut c = RelayClient::connect(args.relay.relay)?;
    let answer = c.request(&format!("GETV {}", args.key))?;
    let b = Binding::parse(&answer).ok_or_else(|| anyhow!("unexpected answer {answer:?}"))?;
    println!("{} {} {} (age {} ms)", b.key, b.ty, b.value, b.age_ms);
    let _ = c.send("QUIT");
    Ok(())
}

/// `huddle set`
pub fn set(args: SetArgs) -> Result<()> {
    let mut c = RelayClient::connect(args.relay.relay)?;
    c.request(&format!("SETV {} {}", args.key, args.value.join(" ")))?;
    let _ = c.send("QUIT");
    Ok(())
}

/// `huddle watch`: a live table of key, owner, value and age, redrawn in place on a
/// terminal; on a pipe, one line per update.
pub fn watch(args: WatchArgs) -> Result<()> {
    let mut c = RelayClient::connect(args.relay.relay)?;
    for p in &args.patterns {
        c.request(&format!("ADDW {p}"))?;
    }
    c.request(&format!("REFR {}", args.interval))?;
    let tty = std::io::stdout().is_terminal();
    let (tx, rx) = mpsc::channel::<String>();
    let mut reader = c.into_reader();
    std::thread::spawn(move || {
        let mut s = String::new();
        while matches!(reader.read_line(&mut s), Ok(n) if n > 0) {
            if tx.send(s.trim_end().to_owned()).is_err() {
                return;
            }
            s.clear();
        }
    });
    let interval = Duration::from_millis(args.interval.max(50));
    let mut table: BTreeMap<String, (Binding, Instant)> = BTreeMap::new();
    let mut next_draw = Instant::now();
    let mut out = std::io::stdout().lock();
    loop {
        let wait = next_draw.saturating_duration_since(Instant::now());
        match rx.recv_timeout(wait) {
            Ok(line) => match Binding::parse(&line) {
                Some(b) if tty => {
                    table.insert(b.key.clone(), (b, Instant::now()));
                }
                Some(b) => writeln!(
                    out,
                    "{}\t{}\t{}\t{} ms",
                    b.key,
                    b.owner(),
                    b.value,
                    b.age_ms
                )?,
                None => eprintln!("relay: {line}"),
            },
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => bail!("the relay closed the connection"),
        }
        if tty && Instant::now() >= next_draw {
            draw(&mut out, &args.patterns, &table)?;
            next_draw = Instant::now() + interval;
        }
    }
}

fn draw(
    out: &mut impl Write,
    patterns: &[String],
    table: &BTreeMap<String, (Binding, Instant)>,
) -> Result<()> {
    // Home, clear screen: redraw in place.
    write!(out, "\x1b[H\x1b[2J")?;
    writeln!(out, "huddle watch {}", patterns.join(" "))?;
    writeln!(out, "{:<40} {:>6} {:>10}  value", "key", "owner", "age")?;
    for (b, seen) in table.values() {
        let age_ms = b.age_ms + seen.elapsed().as_millis() as u64;
        writeln!(
            out,
            "{:<40} {:>6} {:>7} ms  {}",
            b.key,
            b.owner(),
            age_ms,
            b.value
        )?;
    }
    out.flush()?;
    Ok(())
}

/// The daemon's counters as `(name, value, age_ms)`, read from `local.var.huddle.stats.#`.
pub fn fetch_stats(relay: SocketAddr) -> Result<Vec<Binding>> {
    let mut c = RelayClient::connect(relay)?;
    c.request("ADDW local.var.huddle.stats.#")?;
    // REFR pushes the current state at once; QUIT's BYE marks its end.
    c.send("REFR 3600000")?;
    c.send("QUIT")?;
    let lines = c.lines_until("BYE")?;
    Ok(lines.iter().filter_map(|l| Binding::parse(l)).collect())
}

/// `huddle stats`
pub fn stats(args: StatsArgs) -> Result<()> {
    let all = fetch_stats(args.relay.relay)?;
    let name = |b: &Binding| {
        b.key
            .trim_start_matches("local.var.huddle.stats.")
            .to_owned()
    };
    let get = |n: &str| all.iter().find(|b| name(b) == n).map(|b| b.value.clone());
    let or0 = |n: &str| get(n).unwrap_or_else(|| "0".into());
    println!(
        "frames in {}  out {}   bytes in {}  out {}",
        or0("frames_in"),
        or0("frames_out"),
        or0("bytes_in"),
        or0("bytes_out")
    );
    println!(
        "updates applied {}  stale {}   talk delivered {}  given up {}  resent {}  nacks {}",
        or0("updates_applied"),
        or0("updates_stale"),
        or0("talk_delivered"),
        or0("talk_given_up"),
        or0("talk_resent"),
        or0("nacks_sent")
    );
    let drops: Vec<String> = all
        .iter()
        .filter_map(|b| {
            let n = name(b);
            let reason = n.strip_prefix("drops.")?;
            (reason != "total" && b.value != "0").then(|| format!("{reason} {}", b.value))
        })
        .collect();
    println!(
        "drops {}{}",
        or0("drops.total"),
        if drops.is_empty() {
            String::new()
        } else {
            format!(" ({})", drops.join(", "))
        }
    );
    for b in &all {
        let n = name(b);
        if let Some(robot) = n
            .strip_prefix("peer.")
            .and_then(|r| r.strip_suffix(".last_heard_us"))
        {
            // The counter is mirrored once per refresh period when it moves, so its age
            // is the time since the peer was last heard, to within one period.
            println!("peer {robot}: last heard {} ms ago", b.age_ms);
        }
    }
    Ok(())
}
