//! Two network namespaces joined by a veth pair, for tests that need two hosts on one
//! link (broadcast and unicast between them) without a frame leaving the machine: the
//! veth ends live only inside the namespaces, no real interface is touched, and the
//! namespaces (with their veth) are deleted when the guard drops, even on a panic.
//!
//! Needs root (or CAP_NET_ADMIN and CAP_SYS_ADMIN) and iproute2's `ip`: where either
//! is missing, [`NetnsPair::create`] says why and the test skips.

use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};

/// The two addresses on the veth link (10.77.0.0/24: private, inside the namespaces only).
pub const ADDRESSES: [&str; 2] = ["10.77.0.1", "10.77.0.2"];
/// The link's broadcast address.
pub const BROADCAST: &str = "10.77.0.255";

/// Two namespaces `names[0]` (10.77.0.1/24 on `va`) and `names[1]` (10.77.0.2/24 on `vb`),
/// loopback up in both; deleted on drop.
pub struct NetnsPair {
    pub names: [String; 2],
    created: Vec<String>,
}

fn ip(args: &[&str]) -> Result<Output, String> {
    Command::new("ip")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot run `ip` (iproute2): {e}"))
}

fn ip_ok(args: &[&str]) -> Result<(), String> {
    let out = ip(args)?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`ip {}` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl NetnsPair {
    /// Creates the pair, or says why it cannot (not root, no `ip`, no namespaces):
    /// the caller skips with that reason.
    pub fn create(tag: &str) -> Result<NetnsPair, String> {
        let uid = Command::new("id")
            .arg("-u")
            .output()
            .map_err(|e| format!("cannot run `id -u`: {e}"))?;
        let uid = String::from_utf8_lossy(&uid.stdout).trim().to_owned();
        if uid != "0" {
            return Err(format!(
                "needs root to create network namespaces (`id -u` is {uid})"
            ));
        }
        ip(&["-V"])?;
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let names = [0, 1].map(|i| format!("huddle-{tag}-{pid}-{n}-{i}"));
        let mut pair = NetnsPair {
            names: names.clone(),
            created: Vec::new(),
        };
        for name in &names {
            ip_ok(&["netns", "add", name])?;
            pair.created.push(name.clone());
        }
        let [a, b] = &names;
        // The veth is created inside the first namespace, its peer inside the second:
        // neither end ever exists in the host's own namespace.
        ip_ok(&[
            "-n", a, "link", "add", "va", "type", "veth", "peer", "name", "vb", "netns", b,
        ])?;
        for (ns, dev, addr) in [(a, "va", ADDRESSES[0]), (b, "vb", ADDRESSES[1])] {
            ip_ok(&["-n", ns, "addr", "add", &format!("{addr}/24"), "dev", dev])?;
            ip_ok(&["-n", ns, "link", "set", dev, "up"])?;
            ip_ok(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(pair)
    }

    /// A command run inside namespace `i` (`ip netns exec`, which execs the program:
    /// the child is the program itself, so killing it kills the program).
    pub fn command(&self, i: usize, program: &str) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.names[i], program]);
        c
    }
}

impl Drop for NetnsPair {
    fn drop(&mut self) {
        // Deleting a namespace deletes the veth end inside it, and with it the pair.
        for name in self.created.drain(..).rev() {
            if let Err(e) = ip_ok(&["netns", "del", &name]) {
                eprintln!("warning: could not delete network namespace {name}: {e}");
            }
        }
    }
}
