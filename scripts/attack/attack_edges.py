"""Attacks at the relay's edges and on the daemon's own keys (ninth session): lines at
the length limit +-1 cut at every byte near it, many clients' partial lines interleaved,
floods of watch registrations, malformed UTF-8 in keys, writes of the daemon's own keys,
and a GameController storm of stale packet numbers."""

import socket
import threading
import time

from attack_gc import OTHER, TEAM, Gc, gc_stats, rgme, start
from attack_relay import daemon
from harness import Daemon, Relay, check, free_port, scratch_group, seeded

LIMIT = 4096  # the relay's longest line, without its terminator


def edge_line(length, fill):
    """`SETV local.var.edge "..."`, exactly `length` bytes, the string made of `fill`
    (1-4 bytes of UTF-8 each) and padded with 'p' to the length."""
    head, tail = b'SETV local.var.edge "', b'"'
    room = length - len(head) - len(tail)
    f = fill.encode()
    body = f * (room // len(f))
    body += b"p" * (room - len(body))
    line = head + body + tail
    assert len(line) == length
    return line


def line_limit(binary, seed, log, long=False):
    """Lines of 4,095-4,097 bytes (and 4,096 + "\\r"), with 1-4 byte characters that end
    at or straddle the limit, ended by \\n or \\r\\n, each sent whole and cut into two TCP
    writes at every offset within 8 bytes of the limit: up to 4,096 bytes (terminator
    excluded) the value is stored exactly; beyond it, one ERR 402 and the value before
    stays. Every line gets exactly one reply, and the next command runs."""
    rng = seeded(seed, "relay_line_limit")
    d = daemon(binary, rng)
    try:
        c = d.client(timeout=10)
        c.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        cases = ok = refused = 0
        fills = ["y", "\u00e9", "\u20ac", "\U0001f600"]
        for length in (LIMIT - 1, LIMIT, LIMIT + 1):
            for fill in fills:
                line = edge_line(length, fill)
                for end in (b"\n", b"\r\n"):
                    cuts = [None] + list(range(LIMIT - 8, min(len(line) + len(end), LIMIT + 9)))
                    if not long:
                        cuts = [None] + rng.sample(cuts[1:], 4)
                    for cut in cuts:
                        check(c.ask('SETV local.var.edge "before"') == "OK", "reset")
                        data = line + end
                        if cut is None:
                            c.send(data + b"GETV local.var.edge\n")
                        else:
                            c.send(data[:cut])
                            time.sleep(0.002)
                            c.send(data[cut:] + b"GETV local.var.edge\n")
                        reply, after = c.line(), c.line()
                        cases += 1
                        if length <= LIMIT:
                            check(reply == "OK", "a %d-byte line (%r, cut at %s): %r" % (length, fill, cut, reply[:80]))
                            got = after.split(" ", 3)[3].rsplit(" ", 1)[0] if after.startswith("VAL ") else after
                            want = '"%s"' % line[len(b'SETV local.var.edge "'):-1].decode()
                            check(got == want, "a %d-byte line (%r, cut at %s) stored %r" % (length, fill, cut, got[-40:]))
                            ok += 1
                        else:
                            check(reply.startswith("ERR 402"), "a %d-byte line (cut at %s): %r" % (length, cut, reply[:80]))
                            check(after.startswith('VAL local.var.edge string "before"'),
                                  "a refused %d-byte line changed the value: %r" % (length, after[:80]))
                            refused += 1
        # 4,096 bytes then a lone \r, then the newline in another write: the \r is the
        # terminator's.
        line = edge_line(LIMIT, "y")
        c.send(line + b"\r")
        time.sleep(0.002)
        c.send(b"\n")
        check(c.line() == "OK", "4,096 bytes + \\r + \\n in two writes")
        check(c.ask("SETV local.var.after 1") == "OK", "after the edge lines")
        log("  %d lines at the limit +-1 (whole and cut near it): %d stored exactly, %d refused once"
            % (cases, ok, refused))
        d.assert_healthy("line limit")
        return {"lines": cases, "stored": ok, "refused": refused}
    finally:
        d.stop()


def interleaved(binary, seed, log, long=False):
    """Many clients send their lines a few bytes at a time, interleaved with each other
    at random: each gets exactly its own replies, in order, and each key holds the
    value its own client set last."""
    rng = seeded(seed, "relay_interleaved")
    d = daemon(binary, rng)
    try:
        n = 100 if long else 40
        rounds = 20 if long else 8
        clients = [d.client(timeout=10) for _ in range(n)]
        for c in clients:
            c.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        script = []
        for i in range(n):
            lines = []
            for k in range(rounds):
                lines.append(b"SETV local.var.il.c%d %d" % (i, k * 1000 + i))
                lines.append(b"GETV local.var.il.c%d" % i)
            end = rng.choice([b"\n", b"\r\n"])
            script.append(bytearray(end.join(lines) + end))
        sent = 0
        while any(script):
            i = rng.randrange(n)
            if not script[i]:
                continue
            k = rng.randint(1, 7)
            clients[i].send(bytes(script[i][:k]))
            del script[i][:k]
            sent += 1
        for i, c in enumerate(clients):
            for k in range(rounds):
                check(c.line() == "OK", "client %d, SETV %d" % (i, k))
                got = c.line()
                check(got.startswith("VAL local.var.il.c%d int %d " % (i, k * 1000 + i)),
                      "client %d read %r after its SETV %d" % (i, got[:80], k))
        for c in clients:
            c.close()
        log("  %d clients, %d lines each, sent in %d interleaved pieces of 1-7 bytes: every reply its own"
            % (n, 2 * rounds, sent))
        d.assert_healthy("interleaved")
        return {"clients": n, "pieces": sent}
    finally:
        d.stop()


def watch_flood(binary, seed, log, long=False):
    """Clients register watches until refused (256 each, then ERR 429), churn them with
    ADDW/DELW, and watch everything with REFR 0 while a writer writes; half never read.
    The writer is answered throughout, the readers get their updates, the clients that
    never read are cut off and counted in `relay_cutoffs`, memory stays bounded and the
    descriptors come back."""
    rng = seeded(seed, "relay_watch_flood")
    d = daemon(binary, rng)
    watchers = []
    try:
        writer = d.client()
        check(writer.ask("SETV local.var.kept 9") == "OK", "setup")
        rss0, fds0 = d.rss_mib(), d.fds()
        cut0 = writer.stat("relay_cutoffs")
        n = 60 if long else 20
        for i in range(n):
            c = d.client(timeout=10, rcvbuf=4096 if i % 2 else None)
            batch = b"".join(b"ADDW local.var.w.%d.+\n" % k for k in range(256))
            batch += b"ADDW #\nREFR 0\n"
            c.send(batch)
            for k in range(256):
                check(c.line() == "OK", "watcher %d, watch %d" % (i, k))
            a = c.line()
            check(a.startswith("ERR 429"), "the 257th watch: %r" % a)
            check(c.line() == "OK", "REFR 0")
            watchers.append(c)
        # One client churns its watches.
        churn = d.client(timeout=10)
        m = 20_000 if long else 4_000
        for start in range(0, m, 500):
            churn.send(b"".join(b"ADDW local.var.churn.%d\nDELW local.var.churn.%d\n" % (k, k)
                                for k in range(start, start + 500)))
            for _ in range(1000):
                check(churn.line() == "OK", "ADDW/DELW churn")
        churn.send(b"LSTW\n")
        check(churn.line() == "END", "the churned watches are all gone")
        rss1 = d.rss_mib()
        # The even watchers read everything on threads of their own; the odd never read.
        received = [0] * len(watchers[0::2])
        errors = []

        def read_all(i, c):
            c.sock.settimeout(3.0)
            want = writes
            try:
                while received[i] < want:
                    if c.line().startswith("UPD local.var.w."):
                        received[i] += 1
            except (OSError, Exception) as e:  # noqa: BLE001 - counted short, checked below
                errors.append("%s: %s" % (type(e).__name__, e))

        writes = 4000 if long else 2000
        threads = [threading.Thread(target=read_all, args=(i, c), daemon=True)
                   for i, c in enumerate(watchers[0::2])]
        for t in threads:
            t.start()
        # Each non-reader is pushed 7 MB (long: 14 MB): more than the kernel's send
        # buffer on loopback (up to 4 MB, tcp_wmem) and the relay's 1 MiB together.
        for k in range(writes):
            # The readers keep up (Python's threads are slower than the daemon): at most
            # 100 updates (350 KB) behind, well within the relay's 1 MiB.
            deadline = time.monotonic() + 10
            while min(received) < k - 100 and not errors and time.monotonic() < deadline:
                time.sleep(0.001)
            # A new value each time: an unchanged value pushes no update.
            value = '"%06d%s"' % (k, "v" * 3500)
            check(writer.ask("SETV local.var.w.%d.x %s" % (k % 256, value)) == "OK",
                  "the writer was not answered at write %d" % k)
        rss2 = d.rss_mib()
        time.sleep(0.5)
        for t in threads:
            t.join(10)
        cut = writer.stat("relay_cutoffs") - cut0
        check(all(r == writes for r in received),
              "a reading watcher missed updates: %r of %d (%s)" % (received, writes, errors[:2]))
        check(writer.ask("GETV local.var.kept").startswith("VAL local.var.kept int 9 "), "a stored value was lost")
        for c in watchers + [churn]:
            c.close()
        watchers = []
        time.sleep(1.0)
        fds2 = d.fds()
        log("  %d watchers x 256 watches, %d ADDW/DELW churned, %d writes of 3.5 KB: RSS %.1f -> %.1f -> %.1f MiB, "
            "%d non-readers cut off (relay_cutoffs), descriptors %d -> %d"
            % (n, m, writes, rss0, rss1, rss2, cut, fds0, fds2))
        check(rss2 - rss0 < 200, "%.0f MiB for %d watchers" % (rss2 - rss0, n))
        check(cut == n // 2, "%d clients cut off (relay_cutoffs), %d never read" % (cut, n // 2))
        check(fds2 <= fds0 + 5, "descriptors not given back: %d -> %d" % (fds0, fds2))
        d.assert_healthy("watch flood")
        return {"watchers": n, "cut": cut, "rss_mib": round(rss2 - rss0, 1)}
    finally:
        for c in watchers:
            c.close()
        d.stop()


UTF8_BAD = [b"\xc0\xaf", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80", b"\x80", b"\xe2\x82", b"\xff",
            b"\xf4\x90\x80\x80", b"\xe0\x80\xaf", b"\xc3"]
UTF8_GOOD = ["\u00e9", "\u65e5\u672c", "\U0001f600", "\u03a9mega", "a\u0301", "\ufeffbom"]


def utf8_keys(binary, seed, log, long=False):
    """Keys with malformed UTF-8 (overlong, surrogate, 5-byte, lone continuation, cut
    short at the line's end, beyond U+10FFFF) in every verb: one refusal each (403),
    nothing stored. Keys of valid non-ASCII text are refused by the key syntax (410:
    ASCII letters, digits, - and _) in every verb alike, on one line each, and so are
    watch patterns of it (411: they could never match a key), all counted in
    `relay_non_ascii_refused`; the same text as a string value is stored, read and
    pushed byte for byte."""
    rng = seeded(seed, "relay_utf8_keys")
    d = daemon(binary, rng)
    try:
        c = d.client()
        check(c.ask("SETV local.var.kept 3") == "OK", "setup")
        refused = 0
        for bad in UTF8_BAD:
            for verb in (b"SETV", b"SETP", b"GETV", b"ADDW", b"DELW"):
                key = b"local.var.k" + bad + (rng.choice([b"", b".x"]))
                line = verb + b" " + key + (b" 1" if verb.startswith(b"SET") else b"")
                a = c.ask(line)
                check(a.startswith("ERR 403"), "%r: %r" % (line, a[:80]))
                refused += 1
        c.send(b"ADDW local.var.u.#\nREFR 0\n")
        check(c.line() == "OK" and c.line() == "OK", "watch")
        w = d.client()
        non_ascii0 = w.stat("relay_non_ascii_refused")
        syntax = patterns = 0
        for i, good in enumerate(UTF8_GOOD):
            key = "local.var.u.%s" % good
            for verb in ("SETV %s %d" % (key, i), "GETV %s" % key):
                a = w.ask(verb)
                check(a.startswith("ERR 410"), "%r: %r" % (verb, a[:80]))
                syntax += 1
            for verb in ("ADDW %s" % key, "DELW %s.#" % key, "ADDW +.var.%s" % good):
                a = w.ask(verb)
                check(a.startswith("ERR 411"), "%r: %r" % (verb, a[:80]))
                patterns += 1
            value = '"%s %d"' % (good, i)
            check(w.ask("SETV local.var.u.s%d %s" % (i, value)) == "OK", "a string of %r" % good)
            upd = c.line()
            check(upd.startswith("UPD local.var.u.s%d string %s " % (i, value)),
                  "the watch pushed %r for %r" % (upd[:80], value))
            check(w.ask("GETV local.var.u.s%d" % i).startswith("VAL local.var.u.s%d string %s " % (i, value)),
                  "GETV of %r" % value)
        w.send(b"LSTW\n")
        check(w.line() == "END", "no watch on the writer")
        check(c.value("local.var.kept") == ("int", "3"), "a stored value was lost")
        w.wait_for("local.var.huddle.stats.relay_non_ascii_refused",
                   lambda v: int(v[1]) == non_ascii0 + syntax + patterns)
        log("  %d lines with malformed UTF-8 in the key refused (403); %d uses of non-ASCII keys refused by the key "
            "syntax (410) and %d non-ASCII watch patterns (411), all counted; %d non-ASCII strings stored, "
            "read and pushed exactly" % (refused, syntax, patterns, len(UTF8_GOOD)))
        d.assert_healthy("utf-8 keys")
        return {"refused": refused, "syntax": syntax, "patterns": patterns, "strings": len(UTF8_GOOD)}
    finally:
        d.stop()


OWN_KEYS = ["local.var.team.ball", "local.var.team.goer", "local.var.team", "local.var.team.x.y",
            "local.var.gc.state", "local.var.gc.penalized", "local.var.gc.new",
            "local.var.huddle.stats.frames_in", "local.var.huddle.stats.relay_read_only_refused",
            "local.var.huddle.x"]
NOT_OWN = ["local.var.teams.x", "local.var.gcx", "local.var.huddle_client.x", "local.var.x.team",
           "*.var.team.ball", "*.var.gc.state", "*.var.huddle.x"]


def read_only(binary, seed, log, long=False):
    """A program writes the daemon's own keys (the team layer's outputs, the GC's game
    state, the counters), in SETV, SETP and lower case, with values of every type: each
    is refused with ERR 423, nothing is written, and `relay_read_only_refused` counts
    them. Keys that only look alike are ordinary. A daemon without the team layer and the
    listener takes their families as ordinary keys; its counters stay its own."""
    rng = seeded(seed, "relay_read_only")
    group, port = scratch_group(rng)
    gc_port = free_port(socket.SOCK_DGRAM)
    gc = Gc(("127.0.0.1", gc_port))
    d = Daemon(binary, 1, ["--group", "%s:%d" % (group, port), "--team", str(TEAM)],
               ["--gamecontroller", "--gc-listen", "127.0.0.1:%d" % gc_port,
                "--gc-status-port", str(gc.status_port)])
    plain = None
    try:
        c = d.client()
        gc.send(rgme(1, state=3, secs=500))
        c.wait_for("local.var.gc.state", lambda v: v == ("string", '"playing"'))
        check(c.ask("SETV local.var.robot.pose [0.5, -1.0, 0.25, 0.01, 0, 0, 0.01, 0, 0.003]") == "OK", "pose")
        c.wait_for("local.var.team.tick", lambda v: v[0] == "int")
        before = {k: c.value(k) for k in OWN_KEYS if k.startswith("local.var.gc.")}
        refused0 = c.stat("relay_read_only_refused")
        values = ["1", "-2.5", "true", '"playing"', "[1, 2]", "[1e300, -0.0]", "0x00ff"]
        n = 0
        for key in OWN_KEYS:
            for verb in ("SETV", "SETP", "setv"):
                for spelled in (key, key.replace("local", "LOCAL", 1)):
                    line = "%s %s %s" % (verb, spelled, rng.choice(values))
                    a = c.ask(line)
                    if a.startswith("ERR 410"):  # a scope spelled in capitals may not parse
                        continue
                    check(a.startswith("ERR 423 "), "%s: %r" % (line, a[:100]))
                    n += 1
        for key in NOT_OWN:
            check(c.ask("SETV %s 7" % key) == "OK", "%s is not the daemon's: refused" % key)
        after = {k: c.value(k) for k in before}
        check(after == before, "refused writes changed the game: %r -> %r" % (before, after))
        time.sleep(0.3)
        counted = c.stat("relay_read_only_refused") - refused0
        check(counted == n, "relay_read_only_refused moved by %d for %d refusals" % (counted, n))
        d.assert_healthy("read-only keys")

        plain = Daemon(binary, 2, ["--group", "%s:%d" % (group, port), "--team", str(TEAM)],
                       ["--no-team-layer", "--no-gamecontroller"])
        p = plain.client()
        for key in ("local.var.team.ball", "local.var.gc.state"):
            check(p.ask("SETV %s 1" % key) == "OK", "%s without its writer: refused" % key)
        check(p.ask("SETV local.var.huddle.x 1").startswith("ERR 423 "), "the counters are always the daemon's")
        log("  %d writes of the daemon's own keys refused (ERR 423) and counted; %d look-alikes taken; "
            "without the team layer and the listener their keys are ordinary" % (n, len(NOT_OWN)))
        plain.assert_healthy("read-only keys, plain daemon")
        return {"refused": n}
    finally:
        gc.stop()
        d.stop()
        if plain:
            plain.stop()


def gc_stale_storm(binary, seed, log, long=False):
    """The GC sends every 500 ms, in order, as GameController3 does; between its packets
    a storm of packets with stale numbers (the same as its newest, or up to 128 behind,
    never the restart rule's 0), each saying another state, clock, budget, penalty and
    team order: only the GC's own are accepted, every stale one is counted stale (or
    dropped by the kernel), and the game on the blackboard is the GC's newest. (Without
    a newer packet for 2 s the tracker takes the next packet afresh, whatever its
    number, for a GC restarted on another machine: a storm without the GC's packets
    lasts no longer than that.)"""
    rng = seeded(seed, "gc_stale_storm")
    d, gc = start(binary, rng)
    try:
        c = d.client()
        last = rng.randrange(1, 256)
        secs, budget = 321, 777
        gc.send(rgme(last, state=3, secs=secs, budget=budget))
        c.wait_for("local.var.gc.secs_remaining", lambda v: v == ("int", str(secs)))
        keys = ["local.var.gc.state", "local.var.gc.secs_remaining", "local.var.gc.budget",
                "local.var.gc.penalty", "local.var.gc.penalized"]
        before = gc_stats(c)
        kernel0 = d.udp_drops()
        n = 50_000 if long else 5_000
        genuine = 0
        next_genuine = time.monotonic() + 0.5
        for i in range(n):
            if time.monotonic() >= next_genuine:
                last, secs, budget = (last + 1) % 256 or 1, secs - 1, budget - 1
                gc.send(rgme(last, state=3, secs=secs, budget=budget))
                genuine += 1
                next_genuine += 0.5
            number = (last - rng.randint(0, 128)) % 256
            if number == 0:
                number = last
            gc.send(rgme(number, state=rng.choice([0, 1, 2, 4, 5]), secs=rng.randint(-32768, 32767),
                         budget=rng.randrange(65536), penalties={1: (rng.randint(1, 14), rng.randrange(256))},
                         teams=rng.choice([(TEAM, OTHER), (OTHER, TEAM)])))
            if i % 500 == 0:
                check(c.ask("SETV *.var.x %d" % i) == "OK", "the relay stopped answering in the storm")
        time.sleep(0.5)
        kernel = d.udp_drops() - kernel0
        d_ = {k: v - before[k] for k, v in gc_stats(c).items()}
        now = {k: c.value(k) for k in keys}
        want = {"local.var.gc.state": ("string", '"playing"'), "local.var.gc.secs_remaining": ("int", str(secs)),
                "local.var.gc.budget": ("int", str(budget)), "local.var.gc.penalty": ("int", "0"),
                "local.var.gc.penalized": ("floats", "[]")}
        # A genuine packet the kernel dropped leaves the game one packet behind, never
        # at a stale one's.
        check(d_["accepted"] + kernel >= genuine and d_["accepted"] <= genuine,
              "%d accepted of %d genuine packets (%d kernel drops)" % (d_["accepted"], genuine, kernel))
        if d_["accepted"] == genuine:
            check(now == want, "stale packets moved the game: %r, the GC said %r" % (now, want))
        else:
            check(now["local.var.gc.state"] == want["local.var.gc.state"], "the game moved: %r" % (now,))
        check(d_["stale"] + d_["accepted"] + kernel == n + genuine,
              "stale %d + accepted %d + kernel drops %d != %d sent" % (d_["stale"], d_["accepted"], kernel, n + genuine))
        gc.send(rgme((last + 1) % 256 or 1, state=3, secs=secs - 1, budget=budget - 1))
        c.wait_for("local.var.gc.secs_remaining", lambda v: v == ("int", str(secs - 1)))
        log("  %d stale packets in a storm around %d of the GC's own: %d counted stale, %d accepted, "
            "%d dropped by the kernel; the game is the GC's newest" % (n, genuine, d_["stale"], d_["accepted"], kernel))
        d.assert_healthy("gc stale storm")
        return {"packets": n, "genuine": genuine, "stale": d_["stale"], "kernel": kernel}
    finally:
        gc.stop()
        d.stop()
