"""Real `huddle daemon`s on loopback, raw relay clients and loopback-only senders.

Everything binds 127.0.0.1 and sends only to a scratch multicast group with
IP_MULTICAST_IF 127.0.0.1 (loop on, TTL 1), to 127.0.0.1 or to 127.255.255.255.
"""

import os
import random
import socket
import subprocess
import tempfile
import time


class Failure(AssertionError):
    """An invariant the attack suite checks did not hold."""


def check(cond, what):
    if not cond:
        raise Failure(what)


def free_port(kind=socket.SOCK_STREAM):
    s = socket.socket(socket.AF_INET, kind)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def scratch_group(rng):
    """A 239.255.x.y group and a free port of this run's own."""
    return "239.255.%d.%d" % (rng.randint(1, 254), rng.randint(1, 254)), free_port(socket.SOCK_DGRAM)


def team_net(group, port, team):
    """The daemon flags that put a robot on this run's group, in `team`."""
    return ["--group", "%s:%d" % (group, port), "--team", str(team)]


# A plausible robot pose for `local.var.robot.pose` (x, y, heading and its covariance).
ROBOT_POSE = "[0.5, -1.0, 0.25, 0.01, 0, 0, 0.01, 0, 0.003]"


def multicast_sender():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
    s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
    s.bind(("127.0.0.1", 0))
    return s


class Relay:
    """A raw relay connection: bytes out, lines in, every read with a timeout."""

    def __init__(self, port, timeout=5.0, rcvbuf=None):
        if rcvbuf is None:
            self.sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        else:
            # A small receive buffer set before connecting: a small window, so a client
            # that stops reading leaves its output in the daemon, not in the kernel.
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
            self.sock.settimeout(timeout)
            self.sock.connect(("127.0.0.1", port))
        self.sock.settimeout(timeout)
        self.buf = b""
        self.greeting = self.line()

    def send(self, data):
        self.sock.sendall(data)

    def line(self):
        while b"\n" not in self.buf:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise Failure("the relay closed the connection (buffered %r)" % self.buf[:80])
            self.buf += chunk
        line, self.buf = self.buf.split(b"\n", 1)
        return line.rstrip(b"\r").decode("utf-8", "replace")

    def ask(self, line):
        self.send(line.encode() + b"\n" if isinstance(line, str) else line + b"\n")
        return self.line()

    def stat(self, name):
        a = self.ask("GETV local.var.huddle.stats." + name)
        if not a.startswith("VAL "):
            return 0
        return int(a.split()[3])

    def stats(self, names):
        return {n: self.stat(n) for n in names}

    def value(self, key):
        """(type, value text) of `key`, or None."""
        a = self.ask("GETV " + key)
        if not a.startswith("VAL "):
            return None
        rest = a.split(" ", 3)[3]
        # The value runs to the age (and flags): strip them from the right.
        parts = rest.rsplit(" ", 1)
        while len(parts) == 2 and not parts[1].lstrip("-").isdigit():
            parts = parts[0].rsplit(" ", 1)
        return a.split()[2], parts[0]

    def wait_for(self, key, ok, within=5.0):
        deadline = time.monotonic() + within
        while True:
            v = self.value(key)
            if v is not None and ok(v):
                return v
            if time.monotonic() > deadline:
                raise Failure("%s: still %r after %.1f s" % (key, v, within))
            time.sleep(0.02)

    def close(self):
        try:
            self.sock.close()
        except OSError:
            pass


class Daemon:
    """One `huddle daemon` on loopback; stderr kept for a panic check."""

    def __init__(self, binary, robot, net, extra=(), config_dir=None, env=None):
        self.binary, self.robot = binary, robot
        self.relay_port = free_port()
        self.dir = config_dir or tempfile.mkdtemp(prefix="huddle-attack-")
        self.stderr = open(os.path.join(self.dir, "daemon-%d.log" % robot), "w+b")
        args = [binary, "daemon", "--id", str(robot), "--iface", "127.0.0.1",
                "--relay", "127.0.0.1:%d" % self.relay_port, "--config-dir", self.dir]
        args += list(net) + list(extra)
        e = dict(os.environ, RUST_LOG="warn", RUST_BACKTRACE="1")
        e.update(env or {})
        e.pop("HUDDLE_RELAY", None)
        self.args = args
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=self.stderr, env=e)
        self.await_relay()

    def await_relay(self, within=15.0):
        deadline = time.monotonic() + within
        while True:
            if self.proc.poll() is not None:
                raise Failure("daemon %d exited at start (%s): %s"
                              % (self.robot, self.proc.returncode, self.log()[-2000:]))
            try:
                r = Relay(self.relay_port, timeout=2.0)
                g = r.greeting
                r.close()
                if g.endswith("robot %d" % self.robot):
                    return
            except (OSError, Failure):
                pass
            check(time.monotonic() < deadline, "daemon %d's relay never came up" % self.robot)
            time.sleep(0.05)

    def client(self, timeout=5.0, rcvbuf=None):
        return Relay(self.relay_port, timeout, rcvbuf)

    def log(self):
        self.stderr.flush()
        self.stderr.seek(0)
        return self.stderr.read().decode("utf-8", "replace")

    def alive(self):
        return self.proc.poll() is None

    def rss_mib(self):
        with open("/proc/%d/status" % self.proc.pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
        return 0.0

    def fds(self):
        try:
            return len(os.listdir("/proc/%d/fd" % self.proc.pid))
        except OSError:
            return -1

    def udp_drops(self):
        """Datagrams the kernel dropped on this daemon's UDP sockets (full buffers):
        /proc/net/udp's `drops` of the sockets its descriptors name."""
        inodes = set()
        try:
            for fd in os.listdir("/proc/%d/fd" % self.proc.pid):
                try:
                    link = os.readlink("/proc/%d/fd/%s" % (self.proc.pid, fd))
                except OSError:
                    continue
                if link.startswith("socket:["):
                    inodes.add(link[8:-1])
        except OSError:
            return 0
        total = 0
        with open("/proc/%d/net/udp" % self.proc.pid) as f:
            next(f)
            for line in f:
                cols = line.split()
                if cols[9] in inodes:
                    total += int(cols[12])
        return total

    def assert_healthy(self, what):
        """Alive, no panic in its log, and a fresh client is greeted and answered."""
        log = self.log()
        check("panicked" not in log, "%s: daemon %d panicked:\n%s" % (what, self.robot, log[-3000:]))
        check(self.alive(), "%s: daemon %d exited with %s:\n%s"
              % (what, self.robot, self.proc.returncode, log[-3000:]))
        c = self.client()
        check(c.greeting.endswith("robot %d" % self.robot), "%s: greeting %r" % (what, c.greeting))
        check(c.ask("SETV local.var.attack.alive 1") == "OK", "%s: a fresh client's SETV" % what)
        c.close()

    def stop(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.stderr.close()


def seeded(seed, salt):
    return random.Random("%s/%s" % (seed, salt))
