"""Attacks on the relay's TCP line protocol, and config files that are not config."""

import os
import socket
import subprocess
import time

from harness import Daemon, Relay, check, scratch_group, seeded

REPLY = ("OK", "ERR ", "VAL ")
VERBS = ["GETV", "SETV", "SETP", "CLOK", "DELW", "CLRW", "getv", "SeTv", "FROB", ""]
KEYS = ["local.var.a", "*.var.b", "*.talk.q", "1.var.c", "local.var.", ".var.x", "local.var.a.b.c.d",
        "local.var.\u00e9", "local.var.a b", "*.var.#", "+.var.x", "255.var.x", "local.talk.q",
        "local.var." + "k" * 300, "local.var.a..b", "LOCAL.VAR.A"]
VALUES = ["1", "-1", "9223372036854775807", "9223372036854775808", "-9223372036854775809",
          "1.5", "1e308", "1e309", "-0.0", "NaN", "nan", "inf", "-inf", "true", "false", "TRUE",
          '"text"', '"esc \\" \\\\ \\n"', '"unterminated', '"\\q"', "[]", "[1, 2.5]", "[1,", "[[1]]",
          "[NaN, inf]", "0x", "0x0a0b", "0xabc", "0xzz", "word", "-", ".", "+1", "1_000", "[" * 100,
          '"' + "x" * 3000 + '"', "0x" + "ab" * 1500]


def daemon(binary, rng, robot=4, extra=()):
    group, port = scratch_group(rng)
    return Daemon(binary, robot, ["--group", "%s:%d" % (group, port)], extra)


def random_line(rng):
    r = rng.random()
    if r < 0.15:
        # Raw bytes, no newline and never only blanks.
        b = bytes(rng.randrange(256) for _ in range(rng.randint(1, 60))).replace(b"\n", b"")
        return b.strip() or b"x"  # a blank line (spaces, tabs, \f, \v) gets no reply
    verb = rng.choice(VERBS)
    parts = [verb, rng.choice(KEYS)]
    if verb.upper() in ("SETV", "SETP") or rng.random() < 0.2:
        parts.append(rng.choice(VALUES))
    if rng.random() < 0.1:
        parts.append(rng.choice(VALUES))
    line = " ".join(p for p in parts if p).encode()
    if rng.random() < 0.1:
        i = rng.randrange(len(line) + 1)
        line = line[:i] + rng.choice([b"\xff", b"\xc3\x28", b"\x00", b"\t", b"\r", b"\xe2\x82"]) + line[i:]
    if rng.random() < 0.2:
        line += b"\r"
    return line.strip() or b"x"


def lines(binary, seed, log, long=False):
    """Random and mutated command lines pipelined: exactly one reply each, of a known
    form; a value set is read back the same, and its text sets the same value again."""
    rng = seeded(seed, "relay_lines")
    d = daemon(binary, rng)
    try:
        c = d.client()
        check(c.ask('SETV local.var.kept "before"') == "OK", "setup")
        n = 20_000 if long else 2_000
        batch = [random_line(rng) for _ in range(n)]
        counts = {}
        for start in range(0, n, 200):
            chunk = batch[start:start + 200]
            c.send(b"\n".join(chunk) + b"\n")
            for line in chunk:
                reply = c.line()
                check(reply.startswith(REPLY), "%r answered %r" % (line[:60], reply[:80]))
                key = reply[:7] if reply.startswith("ERR") else reply[:2]
                counts[key] = counts.get(key, 0) + 1
        # Every local value set reads back, and its text parses to the same value.
        c.send(b"ADDW local.var.#\nLSTW\n")
        check(c.line() == "OK", "ADDW")
        check(c.line().startswith("WATCH"), "LSTW")
        check(c.line() == "END", "LSTW END")
        roundtrips = 0
        for key in ["local.var.a", "local.var.a.b.c.d", "local.var.\u00e9", "local.var." + "k" * 300]:
            v = c.value(key)
            if v is None:
                continue
            check(c.ask("SETV local.var.echo %s" % v[1]) == "OK", "%s's value %r does not parse back" % (key, v[1][:60]))
            check(c.value("local.var.echo") == v, "%s: %r read back as %r" % (key, v, c.value("local.var.echo")))
            roundtrips += 1
        for text in VALUES:
            if c.ask("SETV local.var.rt %s" % text) != "OK":
                continue
            v = c.value("local.var.rt")
            check(c.ask("SETV local.var.rt2 %s" % v[1]) == "OK", "%r printed %r, which does not parse" % (text, v[1][:60]))
            check(c.value("local.var.rt2") == v, "%r: %r then %r" % (text, v, c.value("local.var.rt2")))
            roundtrips += 1
        check(c.value("local.var.kept") == ("string", '"before"'), "the stored value was lost")
        log("  %d lines, one reply each (%s); %d values printed and parsed back the same"
            % (n, ", ".join("%s %d" % kv for kv in sorted(counts.items())), roundtrips))
        d.assert_healthy("relay lines")
        return {"lines": n, "roundtrips": roundtrips}
    finally:
        d.stop()


def long_lines(binary, seed, log, long=False):
    """Lines at and over the 4 KiB limit, up to 16 MiB with no newline, each refused
    once; the next command runs."""
    rng = seeded(seed, "relay_long")
    d = daemon(binary, rng)
    try:
        c = d.client(timeout=30)
        sizes = [4094, 4095, 4096, 4097, 65536, 1 << 20] + ([16 << 20] if long else [4 << 20])
        out = []
        for size in sizes:
            prefix = b"SETV local.var.big \""
            body = prefix + b"y" * max(0, size - len(prefix) - 1) + b"\""
            c.send(body + b"\nGETV local.var.kept2\n")
            first = c.line()
            second = c.line()
            check(first.startswith(("OK", "ERR 402", "ERR 422")), "a %d-byte line: %r" % (size, first[:80]))
            check(second.startswith("ERR 404"), "the line after a %d-byte line: %r" % (size, second[:80]))
            out.append("%d B: %s" % (size, first[:7]))
        check(c.ask("SETV local.var.after 1") == "OK", "after the long lines")
        log("  " + ", ".join(out))
        d.assert_healthy("long lines")
        return {"sizes": sizes}
    finally:
        d.stop()


def half_lines(binary, seed, log, long=False):
    """Half a command, then the client goes: never executed, and the daemon carries on."""
    rng = seeded(seed, "relay_half")
    d = daemon(binary, rng)
    try:
        n = 2_000 if long else 300
        for i in range(n):
            s = socket.create_connection(("127.0.0.1", d.relay_port), timeout=5)
            cut = rng.choice([b"SETV local.var.half %d" % i, b"SETV local.var.half", b"SET",
                              b"SETV local.var.half \"open", b"\xff\xfe", b"GETV local.var.half\r"])
            if rng.random() < 0.5:
                s.recv(64)  # the greeting
            s.sendall(cut)
            if rng.random() < 0.3:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")  # RST
            s.close()
        time.sleep(0.3)
        c = d.client()
        v = c.value("local.var.half")
        check(v is None, "a half line was executed: local.var.half = %r" % (v,))
        log("  %d clients sent half a line and left: none executed" % n)
        d.assert_healthy("half lines")
        return {"clients": n}
    finally:
        d.stop()


def connections(binary, seed, log, long=False):
    """Thousands of clients at once, most silent, on a daemon whose --max-clients lets
    them all in: each greeted, the daemon answers the last one, and its descriptors and
    memory come back when they go."""
    rng = seeded(seed, "relay_conns")
    n = 4_000 if long else 1_000
    d = daemon(binary, rng, extra=["--max-clients", str(n + 16)])
    try:
        c = d.client()
        check(c.ask("SETV local.var.kept 5") == "OK", "setup")
        fds0, rss0 = d.fds(), d.rss_mib()
        socks, greeted = [], 0
        for i in range(n):
            s = socket.create_connection(("127.0.0.1", d.relay_port), timeout=10)
            socks.append(s)
        for s in socks:
            if s.recv(64).startswith(b"HUDDLE"):
                greeted += 1
        fds1, rss1 = d.fds(), d.rss_mib()
        last = Relay(d.relay_port)
        check(last.ask("GETV local.var.kept").startswith("VAL local.var.kept int 5 "), "with %d clients" % n)
        for s in socks:
            s.close()
        time.sleep(1.0)
        fds2 = d.fds()
        log("  %d clients at once: %d greeted; descriptors %d -> %d -> %d, RSS %.1f -> %.1f MiB"
            % (n, greeted, fds0, fds1, fds2, rss0, rss1))
        check(greeted == n, "%d of %d clients greeted" % (greeted, n))
        check(fds2 <= fds0 + 5, "descriptors not given back: %d -> %d" % (fds0, fds2))
        check(rss1 - rss0 < 200, "%.0f MiB for %d clients" % (rss1 - rss0, n))
        d.assert_healthy("connections")
        return {"clients": n, "rss_mib": round(rss1 - rss0, 1)}
    finally:
        d.stop()


CAP = 64  # huddle daemon's default --max-clients
REFUSAL = "ERR 503 too many relay clients (%d connected, --max-clients)" % CAP


def first_line_then_eof(s, within=5.0):
    """The first line a connection gets, and, for an `ERR` line, whether the daemon closed
    the connection after it with nothing more."""
    s.settimeout(within)
    buf = b""
    try:
        while b"\n" not in buf:
            chunk = s.recv(256)
            if not chunk:
                return buf.decode("utf-8", "replace"), True
            buf += chunk
        line, rest = buf.split(b"\n", 1)
        if rest or not line.startswith(b"ERR "):
            return line.decode("utf-8", "replace"), False  # a greeting: served, stays open
        s.settimeout(0.5)
        try:
            closed = s.recv(64) == b""
        except socket.timeout:
            closed = False
        except OSError:
            closed = True
        return line.decode("utf-8", "replace"), closed
    except (socket.timeout, OSError):
        return buf.decode("utf-8", "replace"), False


def client_cap(binary, seed, log, long=False):
    """One host opens 1,000 (long: 4,000) connections while a few clients work: the
    daemon serves 64 at most (its default --max-clients), each connection over the cap
    gets one line `ERR 503` and is closed, the refusals are counted, the working clients
    never notice, and descriptors and memory come back."""
    rng = seeded(seed, "relay_client_cap")
    d = daemon(binary, rng)
    try:
        k = rng.randint(3, 12)
        workers = [d.client() for _ in range(k)]
        for i, w in enumerate(workers):
            check(w.ask("SETV local.var.e%d %d" % (i, i)) == "OK", "setup %d" % i)
        watcher = workers[0]
        watcher.send(b"ADDW local.var.w\nREFR 0\n")
        check(watcher.line() == "OK" and watcher.line() == "OK", "watch")
        refused0 = watcher.stat("relay_clients_refused")
        fds0, rss0 = d.fds(), d.rss_mib()
        n = 4_000 if long else 1_000
        socks = []
        for i in range(n):
            socks.append(socket.create_connection(("127.0.0.1", d.relay_port), timeout=10))
            if i % 97 == 0:
                # The working clients are answered in the middle of the flood.
                j = rng.randrange(k)
                v = workers[j].value("local.var.e%d" % j)
                check(v == ("int", str(j)), "client %d during the flood: %r" % (j, v))
        greeted, refused, odd = [], 0, []
        for s in socks:
            line, closed = first_line_then_eof(s)
            if line.startswith("HUDDLE "):
                greeted.append(s)
            elif line.startswith(REFUSAL) and closed:
                refused += 1
            else:
                odd.append((line[:80], closed))
        fds1, rss1 = d.fds(), d.rss_mib()
        check(not odd, "%d connections neither greeted nor refused with one line: %r" % (len(odd), odd[:5]))
        check(len(greeted) + k == CAP, "%d greeted beside %d working clients, cap %d" % (len(greeted), k, CAP))
        check(refused == n - len(greeted), "%d refused of %d" % (refused, n))
        # The working clients: each reads its value, one writes, the watcher is pushed it.
        for j, w in enumerate(workers):
            check(w.value("local.var.e%d" % j) == ("int", str(j)), "client %d after the flood" % j)
        check(workers[-1].ask("SETV local.var.w 7") == "OK", "a write after the flood")
        upd = watcher.line()
        check(upd.startswith("UPD local.var.w int 7 "), "the watcher was pushed %r" % upd[:80])
        # A greeted one of the flood works too.
        if greeted:
            r = greeted[0]
            r.settimeout(5)
            r.sendall(b"GETV local.var.e0\n")
            check(r.recv(256).startswith(b"VAL local.var.e0 int 0 "), "a greeted flood client")
        watcher.wait_for("local.var.huddle.stats.relay_clients_refused",
                         lambda v: int(v[1]) == refused0 + refused)
        for s in socks:
            s.close()
        time.sleep(1.0)
        fds2 = d.fds()
        # Room again: a newcomer is greeted.
        late = d.client()
        check(late.greeting.startswith("HUDDLE "), "a newcomer after the flood: %r" % late.greeting)
        log("  %d working clients; %d connections: %d greeted, %d refused with ERR 503 and counted; "
            "descriptors %d -> %d -> %d, RSS %.1f -> %.1f MiB" % (k, n, len(greeted), refused, fds0, fds1, fds2, rss0, rss1))
        check(fds2 <= fds0 + 5, "descriptors not given back: %d -> %d" % (fds0, fds2))
        check(rss1 - rss0 < 100, "%.0f MiB for %d connections" % (rss1 - rss0, n))
        d.assert_healthy("client cap")
        return {"working": k, "connections": n, "greeted": len(greeted), "refused": refused,
                "rss_mib": round(rss1 - rss0, 1)}
    finally:
        d.stop()


def no_reader(binary, seed, log, long=False):
    """Clients that ask and never read: GETVs of a 3 KB value pipelined without end.
    Each is cut off; the others are answered throughout."""
    rng = seeded(seed, "relay_noreader")
    d = daemon(binary, rng)
    try:
        c = d.client()
        check(c.ask('SETV local.var.blob "%s"' % ("b" * 3000)) == "OK", "setup")
        hogs = []
        for _ in range(3):
            s = socket.create_connection(("127.0.0.1", d.relay_port), timeout=5)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            s.setblocking(False)
            hogs.append(s)
        req = b"GETV local.var.blob\n" * 500
        sent = [0] * len(hogs)
        cut = [False] * len(hogs)
        t0 = time.monotonic()
        while time.monotonic() - t0 < (30 if long else 8) and not all(cut):
            for i, s in enumerate(hogs):
                if cut[i]:
                    continue
                try:
                    sent[i] += s.send(req)
                except BlockingIOError:
                    pass
                except OSError:
                    cut[i] = True
            check(c.ask("GETV local.var.blob").startswith("VAL "), "a reading client was not answered")
            time.sleep(0.01)
        log("  3 clients that never read sent %s bytes of requests; cut off: %s"
            % (sent, cut))
        check(all(cut) or max(sent) < (4 << 20),
              "a client that never reads was not cut off after %d bytes of requests" % max(sent))
        d.assert_healthy("no reader")
        return {"sent": sent, "cut": cut}
    finally:
        for s in hogs:
            s.close()
        d.stop()


def config_files(binary, seed, log, long=False):
    """config.dat and config-<id>.dat of garbage: a clear error or a start, never a panic."""
    rng = seeded(seed, "config")
    n = 40 if long else 10
    samples = [b"", b"\xff\xfe\x00", b"x = ", b"*.var.a = [1,", b"local.var.a = " + b"[" * 10000,
               b"1.var.a = 1\n", b"*.talk.q = 1\n", b"*.var.s = \"" + b"z" * 100000 + b"\"\n",
               b"\n".join(b"local.var.k%d = %d" % (i, i) for i in range(70000))]
    while len(samples) < n:
        samples.append(bytes(rng.randrange(256) for _ in range(rng.randint(1, 400))))
    outcomes = {}
    for i, data in enumerate(samples[:n]):
        dirname = os.path.join(os.environ.get("TMPDIR", "/tmp"), "huddle-attack-config-%d-%d" % (os.getpid(), i))
        os.makedirs(dirname, exist_ok=True)
        with open(os.path.join(dirname, rng.choice(["config.dat", "config-4.dat"])), "wb") as f:
            f.write(data)
        group, port = scratch_group(rng)
        p = subprocess.Popen([binary, "daemon", "--id", "4", "--iface", "127.0.0.1", "--group",
                              "%s:%d" % (group, port), "--relay", "127.0.0.1:0", "--config-dir", dirname],
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                             env=dict(os.environ, RUST_LOG="warn", RUST_BACKTRACE="1"))
        try:
            _, err = p.communicate(timeout=3)
            outcome = "exit %d" % p.returncode
        except subprocess.TimeoutExpired:
            p.kill()
            _, err = p.communicate()
            outcome = "ran"
        err = err.decode("utf-8", "replace")
        check("panicked" not in err, "config sample %d: panic:\n%s" % (i, err[-2000:]))
        if outcome.startswith("exit"):
            check(p.returncode != 101 and err.strip(), "sample %d: exit %d without a clear error" % (i, p.returncode))
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
    log("  %d config files: %s" % (n, outcomes))
    return {"files": n}
