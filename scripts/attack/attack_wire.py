"""Attacks on the team's UDP socket: crafted frames with a known fate, mutated frames,
and the same mutations against a daemon with a team key."""

import socket
import struct
import time

import hwire as w
from harness import Daemon, check, free_port, multicast_sender, scratch_group, seeded, team_net

TEAM = 7
DROPS = ["too_short", "oversized", "bad_magic", "unknown_version", "other_team",
         "missing_tag", "unexpected_tag", "bad_tag", "malformed", "replay",
         "retired_incarnation", "robot_id_conflict"]
COUNTERS = ["frames_in", "frames_out", "items_skipped", "updates_applied"] + \
    ["drops." + d for d in DROPS]


def snapshot(client):
    time.sleep(0.35)  # counters are mirrored every refresh (100 ms)
    return client.stats(COUNTERS)


def delta(a, b):
    return {k: b[k] - a[k] for k in a}


def settled(client, before, n, kernel_drops, within=5.0):
    """The counters' change since `before` once all `n` datagrams sent are accounted for
    (counted in, or dropped by the kernel: `kernel_drops()`), or as they stand after
    `within` s; and the kernel's drops. On a loaded machine the daemon may still be
    working through its socket's queue when the sender is done, and its counters are
    mirrored once a refresh and read one at a time: one snapshot can hold `frames_in` of
    one refresh and `drops.*` of the next (seed 1201 at load 18: 3,984 of 4,000)."""
    deadline = time.monotonic() + within
    while True:
        d = delta(before, snapshot(client))
        kernel = kernel_drops()
        if d["frames_in"] - d["frames_out"] + kernel >= n or time.monotonic() > deadline:
            return d, kernel


class Team:
    """Robots 1 and 2 of team 7 on a scratch group, each holding canaries."""

    def __init__(self, binary, rng, extra=()):
        self.group, self.port = scratch_group(rng)
        net = team_net(self.group, self.port, TEAM)
        self.d1 = Daemon(binary, 1, net, extra)
        self.d2 = Daemon(binary, 2, net, extra)
        self.c1, self.c2 = self.d1.client(), self.d2.client()
        check(self.c1.ask('SETV local.var.canary "kept"') == "OK", "canary")
        check(self.c1.ask("SETV *.var.canary 41") == "OK", "canary")
        check(self.c2.ask("SETV *.var.mate 7") == "OK", "mate")
        self.c1.wait_for("2.var.mate", lambda v: v == ("int", "7"))
        self.c2.wait_for("1.var.canary", lambda v: v == ("int", "41"))
        self.sock = multicast_sender()
        self.round = 41

    def send(self, data):
        self.sock.sendto(data, (self.group, self.port))

    def assert_intact(self, what):
        """Both alive, answering, nothing stored lost, and still replicating."""
        for d in (self.d1, self.d2):
            d.assert_healthy(what)
        check(self.c1.value("local.var.canary") == ("string", '"kept"'), what + ": local canary")
        check(self.c1.value("2.var.mate") == ("int", "7"), what + ": robot 2's value on robot 1")
        self.round += 1
        check(self.c1.ask("SETV *.var.canary %d" % self.round) == "OK", what)
        self.c2.wait_for("1.var.canary", lambda v: v == ("int", str(self.round)), 5.0)

    def stop(self):
        self.d1.stop()
        self.d2.stop()


def crafted_cases(rng):
    """(name, bytes, counter that must move by one, key that must then hold or None)."""
    cases = []
    sender = [100]

    def nxt():
        sender[0] += 1
        return sender[0]

    def v4(items, **kw):
        s = kw.pop("sender") if "sender" in kw else nxt()
        return w.frame(TEAM, s, rng.getrandbits(63) | 1, 1, items, **kw), s

    good = w.update("ok", 1)
    cases.append(("empty datagram", b"", "drops.too_short", None))
    cases.append(("one byte", b"H", "drops.too_short", None))
    cases.append(("magic only", b"HD", "drops.too_short", None))
    cases.append(("17-byte header", v4([good])[0][:17], "drops.too_short", None))
    cases.append(("bad magic", b"DH" + v4([good])[0][2:], "drops.bad_magic", None))
    for ver in [0, 1, 2, 5, 6, 99, 255]:
        f, _ = v4([good])
        cases.append(("version %d" % ver, f[:2] + bytes([ver]) + f[3:], "drops.unknown_version", None))
    for flag in [4, 8, 0x80, 0xfc]:
        f, _ = v4([good])
        cases.append(("flags %#x" % flag, f[:3] + bytes([flag]) + f[4:], "drops.malformed", None))
    f, _ = v4([good])
    cases.append(("tagged without a team key", f[:3] + b"\x01" + f[4:] + bytes(16),
                  "drops.unexpected_tag", None))
    f, _ = v4([good])
    cases.append(("another team", f[:4] + bytes([TEAM + 1]) + f[5:], "drops.other_team", None))
    for s in [0, 255]:
        f, _ = v4([good], sender=s)
        cases.append(("sender %d" % s, f, "drops.malformed", None))
    f, _ = v4([good])
    cases.append(("echo flag, no echo", f[:3] + b"\x02" + f[4:18], "drops.too_short", None))
    f, _ = v4([good], echo=(0, 1, 1))
    cases.append(("echo of robot 0", f, "drops.malformed", None))
    cases.append(("no seq", w.header(4, 0, TEAM, nxt(), 5), "drops.malformed", None))
    for marker in [254, 255]:
        cases.append(("seq varint marker %d" % marker,
                      w.header(4, 0, TEAM, nxt(), 5) + bytes([marker]) + bytes(16),
                      "drops.malformed", None))
    cases.append(("seq u64 varint cut", w.header(4, 0, TEAM, nxt(), 5) + b"\xfd\x01\x02",
                  "drops.malformed", None))
    fields = w.update_fields("lie", 5)
    for name, item in [
        ("item length past the body", w.varint(0) + w.varint(len(fields) + 1) + fields),
        ("item length 0", w.varint(0) + w.varint(0) + fields),
        ("item length short of its fields", w.varint(0) + w.varint(len(fields) - 2) + fields),
        ("item length u64::MAX", w.varint(0) + w.varint(2 ** 64 - 1) + fields),
        ("item length 2^32", w.varint(0) + w.varint(2 ** 32) + fields),
        ("unknown type, length past the body", w.varint(77) + w.varint(200) + b"xx"),
        ("type varint cut", b"\xfc\x01"),
        ("length varint missing", w.varint(0)),
        ("bad path", w.update("a..b", 1)),
        ("empty path", w.update("", 1)),
        ("wildcard path", w.update("a.#", 1)),
        ("path of invalid UTF-8", w.item4(0, w.varint(2) + b"\xc3\x28" + w.value(1) + b"\x01\x00")),
        ("string of invalid UTF-8", w.item4(0, w.string("s") + b"\x03\x02\xff\xfe\x01\x00")),
        ("bool 2", w.item4(0, w.string("b") + b"\x02\x02\x01\x00")),
        ("floats claiming 2^32", w.item4(0, w.string("f") + b"\x04" + w.varint(2 ** 32) + bytes(16) + b"\x01\x00")),
        ("bytes claiming 2^63", w.item4(0, w.string("y") + b"\x05" + w.varint(2 ** 63) + bytes(8) + b"\x01\x00")),
        ("string claiming 60000", w.item4(0, w.string("s") + b"\x03" + w.varint(60000) + b"abc\x01\x00")),
        ("talk seq 0", w.item4(1, w.talk_fields("q", 0, 1))),
        ("talk seq 2^62+1", w.item4(1, w.talk_fields("q", 2 ** 62 + 1, 1))),
        ("talk head first 0", w.item4(2, w.head_fields("q", 0, 5))),
        ("talk head first > last + 1", w.item4(2, w.head_fields("q", 9, 5))),
        ("talk head last 2^64-1", w.item4(2, w.head_fields("q", 1, 2 ** 64 - 1))),
        ("nack to robot 0", w.item4(3, w.nack_fields(0, "q", 1, 2))),
        ("nack to robot 255", w.item4(3, w.nack_fields(255, "q", 1, 2))),
        ("nack first > last", w.item4(3, w.nack_fields(1, "q", 3, 2))),
    ]:
        cases.append((name, v4([w.update("before", 1), item])[0], "drops.malformed", None))
    # Format 3: counts that lie, an item it cannot skip, bytes after the items.
    upd3 = w.varint(0) + w.update_fields("v3", 3)
    inc = rng.getrandbits(63) | 1
    cases.append(("format 3 count past its items",
                  w.frame(TEAM, nxt(), inc, 1, [upd3], version=3, count=2), "drops.malformed", None))
    cases.append(("format 3 count 2^64-1",
                  w.frame(TEAM, nxt(), inc, 1, [upd3], version=3, count=2 ** 64 - 1), "drops.malformed", None))
    cases.append(("format 3 bytes after the items",
                  w.frame(TEAM, nxt(), inc, 1, [upd3, b"\x00"], version=3, count=1), "drops.malformed", None))
    cases.append(("format 3 unknown item type",
                  w.frame(TEAM, nxt(), inc, 1, [upd3, w.varint(9) + b"\x00"], version=3), "drops.malformed", None))
    s = nxt()
    cases.append(("format 3 frame", w.frame(TEAM, s, inc, 1, [upd3], version=3), None, ("%d.var.v3" % s, ("int", "3"))))
    # Readable, with what this build must skip (counted) or ignore.
    skip_cases = [
        ("unknown item type 5", w.item4(5, b"future")),
        ("unknown item type 250", w.item4(250, b"")),
        ("unknown item type 2^40", w.item4(2 ** 40, b"\x01\x02")),
        ("value tag 6", w.item4(0, w.string("t6") + b"\x06\x01\x02\x01\x00")),
        ("value tag 255", w.item4(0, w.string("t255") + b"\xff\x01\x00")),
        ("known path index 4", w.item4(4, w.known_fields(4, 1))),
        ("known path index 250", w.item4(4, w.known_fields(250, 1))),
        ("known path index 2^32", w.item4(4, w.known_fields(2 ** 32, 1))),
    ]
    for name, item in skip_cases:
        f, s = v4([item, w.update("after", 9)])
        cases.append((name, f, "items_skipped", ("%d.var.after" % s, ("int", "9"))))
    f, s = v4([w.item4(0, w.update_fields("tail", 4) + b"newer field")])
    cases.append(("fields past the known ones", f, None, ("%d.var.tail" % s, ("int", "4"))))
    f, s = v4([w.update("huge", 1, version=2 ** 64 - 1, age_us=2 ** 64 - 1)])
    cases.append(("version and age u64::MAX", f, None, ("%d.var.huge" % s, ("int", "1"))))
    f, s = v4([w.update("nonfinite", [float("nan"), float("inf"), -float("inf"), -0.0])])
    cases.append(("NaN and infinities", f, None, ("%d.var.nonfinite" % s, None)))
    f, s = v4([w.update("ints", -2 ** 63)])
    cases.append(("i64::MIN", f, None, ("%d.var.ints" % s, ("int", str(-2 ** 63)))))
    f, s = v4([w.update("seq", 1)])
    f = f[:18] + b"\xfd" + struct.pack("<Q", 2 ** 64 - 1) + f[19:]
    cases.append(("seq u64::MAX", f, None, ("%d.var.seq" % s, ("int", "1"))))
    f, s = v4([w.update("echoed", 1)], echo=(1, 65535, 65535), stamp=2 ** 32 - 1)
    cases.append(("an echo of robot 1 at the extremes", f, None, ("%d.var.echoed" % s, ("int", "1"))))
    # The team layer's keys with values of the wrong shape.
    for i, v in enumerate(["claim", 7, [float("nan"), 1.0], [1.0], b"\x00" * 3, [1e308] * 2]):
        f, s = v4([w.item4(4, w.known_fields(0, v)), w.item4(4, w.known_fields(1, v)),
                   w.item4(4, w.known_fields(2, v)), w.item4(4, w.known_fields(3, v)),
                   w.update("shape%d" % i, i)])
        cases.append(("team keys of the wrong shape %d" % i, f, None, ("%d.var.shape%d" % (s, i), ("int", str(i)))))
    f, s = v4([w.item4(4, w.known_fields(1, bytes(rng.getrandbits(8) for _ in range(75)))),
               w.update("lwm", 1)])
    cases.append(("a random 75-byte world model", f, None, ("%d.var.lwm" % s, ("int", "1"))))
    return cases


def crafted(binary, seed, log, long=False):
    """Each crafted frame moves exactly its counter, and the readable ones are applied."""
    rng = seeded(seed, "crafted")
    team = Team(binary, rng)
    try:
        cases = crafted_cases(rng)
        if not long:
            return crafted_at_once(team, cases, log)
        for name, data, counter, holds in cases:
            before = snapshot(team.c1)
            team.send(data)
            after = snapshot(team.c1)
            d = delta(before, after)
            if counter:
                check(d[counter] == 1, "%s: %s moved by %d (%r)" % (name, counter, d[counter],
                                                                     {k: v for k, v in d.items() if v}))
            bad = {k: v for k, v in d.items() if k.startswith("drops.") and k != counter and v}
            check(not bad, "%s: other drop counters moved: %r" % (name, bad))
            if holds:
                key, want = holds
                got = team.c1.wait_for(key, lambda v: want is None or v == want, 3.0)
                log("  %-40s -> %s" % (name, "%s = %s" % (key, got[1][:40])))
            else:
                log("  %-40s -> %s +1" % (name, counter))
        team.assert_intact("crafted frames")
        return {"cases": len(cases)}
    finally:
        team.stop()


def crafted_at_once(team, cases, log):
    """The short run: every case sent in one go, the counters' sums checked."""
    want = {}
    before = snapshot(team.c1)
    for name, data, counter, holds in cases:
        team.send(data)
        if counter:
            want[counter] = want.get(counter, 0) + 1
        time.sleep(0.002)
    d = delta(before, snapshot(team.c1))
    for counter, n in want.items():
        check(d[counter] == n, "%s moved by %d, %d cases expect it" % (counter, d[counter], n))
    bad = {k: v for k, v in d.items() if k.startswith("drops.") and v and k not in want}
    check(not bad, "other drop counters moved: %r" % bad)
    for name, data, counter, holds in cases:
        if holds:
            key, v = holds
            team.c1.wait_for(key, lambda got: v is None or got == v, 3.0)
    log("  %d crafted frames: %s" % (len(cases), ", ".join("%s +%d" % kv for kv in sorted(want.items()))))
    team.assert_intact("crafted frames")
    return {"cases": len(cases)}


def mutate(rng, data):
    """One of: bit flips, a byte set, a cut, an insertion, a slice repeated, a varint
    widened to u64, or a length or count byte that lies; never the frame unchanged."""
    while True:
        b = mutate_once(rng, data)
        if b != data:
            return b


def mutate_once(rng, data):
    b = bytearray(data)
    kind = rng.randrange(8) if len(b) > 1 else 3
    if kind == 0:
        for _ in range(rng.randint(1, 8)):
            i = rng.randrange(len(b) * 8)
            b[i // 8] ^= 1 << (i % 8)
    elif kind == 1:
        b[rng.randrange(len(b))] = rng.choice([0, 0xff, 0xfb, 0xfc, 0xfd, 0xfe, rng.randrange(256)])
    elif kind == 2:
        del b[rng.randrange(len(b)):]
    elif kind == 3:
        i = rng.randrange(len(b) + 1)
        b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    elif kind == 4:
        i = rng.randrange(len(b))
        j = rng.randint(i, min(len(b), i + 32))
        b[j:j] = b[i:j] * rng.randint(1, 4)
    elif kind == 5:
        i = rng.randrange(w.HEADER_LEN, len(b)) if len(b) > w.HEADER_LEN else 0
        b[i:i + 1] = b"\xfd" + struct.pack("<Q", rng.choice([2 ** 64 - 1, 2 ** 63, 2 ** 32, rng.getrandbits(64)]))
    elif kind == 6:
        i = rng.randrange(w.HEADER_LEN, len(b)) if len(b) > w.HEADER_LEN else 0
        b[i] = rng.choice([0, 1, 250, 251, 252, 253, 254, 255])
    else:
        b = b[:w.HEADER_LEN] + bytes(rng.randrange(256) for _ in range(rng.randint(0, 200)))
    if len(b) > 5 and b[5] in (1, 2):
        b[5] = 150  # never forge the two robots whose canaries are checked
    return bytes(b)


def base_frames(rng, key=None):
    out = []
    for version in (4, 3):
        items = [
            (w.ITEM_UPDATE, w.update_fields("m.%d" % rng.randrange(50), rng.randrange(-999, 999), rng.randint(1, 300), rng.randrange(10 ** 6))),
            (w.ITEM_UPDATE, w.update_fields("s", "text \u00e9", 2, 0)),
            (w.ITEM_UPDATE, w.update_fields("f", [rng.random() for _ in range(rng.randint(0, 6))], 3, 9)),
            (w.ITEM_KNOWN, w.known_fields(rng.randrange(4), [rng.random(), 0.0], 4, 1)),
            (w.ITEM_TALK, w.talk_fields("plan", rng.randint(1, 9), b"\x01\x02")),
            (w.ITEM_TALK_HEAD, w.head_fields("plan", 1, rng.randint(1, 9))),
            (w.ITEM_NACK, w.nack_fields(rng.randint(3, 9), "plan", 1, 2)),
        ]
        rng.shuffle(items)
        if version == 4:
            enc = [w.item4(t, f) for t, f in items] + [w.item4(rng.randint(5, 300), b"future")]
        else:
            enc = [w.varint(t) + f for t, f in items]
        echo = (rng.randint(1, 254), rng.getrandbits(16), rng.getrandbits(16)) if rng.random() < 0.5 else None
        out.append(w.frame(TEAM, rng.randint(100, 200), rng.getrandbits(64), rng.getrandbits(20),
                           enc, key=key, stamp=rng.getrandbits(32), echo=echo, version=version))
    return out


def mutated(binary, seed, log, long=False):
    """Mutated frames to a team of two (it must stay intact and replicating) and to a
    robot alone on a group of its own (every datagram must be accounted for: counted
    in, and dropped, skipped or applied)."""
    rng = seeded(seed, "mutated")
    n = 60_000 if long else 4_000
    team = Team(binary, rng)
    group, port = scratch_group(rng)
    solo = Daemon(binary, 5, team_net(group, port, TEAM))
    try:
        c5 = solo.client()
        before = snapshot(c5)
        kernel0 = solo.udp_drops()
        rss0 = solo.rss_mib()
        for i in range(n):
            data = mutate(rng, rng.choice(base_frames(rng)))
            for _ in range(rng.choice([0, 0, 0, 1, 2])):
                data = mutate(rng, data)
            team.send(data)
            team.sock.sendto(data, (group, port))
            if i % 100 == 99:
                time.sleep(0.01)
        d, kernel = settled(c5, before, n, lambda: solo.udp_drops() - kernel0)
        mine = d["frames_in"] - d["frames_out"] + kernel
        drops = sum(v for k, v in d.items() if k.startswith("drops."))
        log("  %d mutated frames: counted in %d (%d dropped by the kernel, full buffer), %d dropped (%s), "
            "%d items skipped, %d updates applied, RSS %.1f -> %.1f MiB"
            % (n, mine, kernel, drops, ", ".join("%s %d" % (k[6:], v) for k, v in d.items() if k.startswith("drops.") and v),
               d["items_skipped"], d["updates_applied"], rss0, solo.rss_mib()))
        check(abs(mine - n) <= 2, "datagrams in %d, sent %d: some were not counted" % (mine, n))
        check(drops <= n, "more drops than frames")
        solo.assert_healthy("mutated frames")
        team.assert_intact("mutated frames")
        return {"frames": n, "dropped": drops, "skipped": d["items_skipped"]}
    finally:
        team.stop()
        solo.stop()


def keyed(binary, seed, log, long=False):
    """With a team key, no mutated or forged frame applies anything: every one dropped."""
    rng = seeded(seed, "keyed")
    n = 30_000 if long else 2_000
    key = bytes(rng.getrandbits(8) for _ in range(32)).hex().encode()
    group, port = scratch_group(rng)
    d = Daemon(binary, 1, team_net(group, port, TEAM), [])
    keyfile = d.dir + "/team.key"
    d.stop()
    with open(keyfile, "wb") as f:
        f.write(key + b"\n")
    d = Daemon(binary, 1, team_net(group, port, TEAM), ["--key-file", keyfile])
    sock = multicast_sender()
    try:
        c = d.client()
        # A correctly keyed frame is applied (the key and the tag are as the docs say).
        good = w.frame(TEAM, 42, 5, 1, [w.update("keyed", 1)], key=key)
        sock.sendto(good, (group, port))
        c.wait_for("42.var.keyed", lambda v: v == ("int", "1"), 3.0)
        before = snapshot(c)
        kernel0 = d.udp_drops()
        for i in range(n):
            data = mutate(rng, rng.choice(base_frames(rng, key=key)))
            sock.sendto(data, (group, port))
            if i % 100 == 99:
                time.sleep(0.01)
        dl, kernel = settled(c, before, n, lambda: d.udp_drops() - kernel0)
        mine = dl["frames_in"] - dl["frames_out"] + kernel
        drops = sum(v for k, v in dl.items() if k.startswith("drops.")) + kernel
        log("  %d mutated keyed frames: %d in, %d dropped (%s), %d updates applied"
            % (n, mine, drops, ", ".join("%s %d" % (k[6:], v) for k, v in dl.items() if k.startswith("drops.") and v),
               dl["updates_applied"]))
        check(abs(mine - n) <= 3, "datagrams in %d, sent %d" % (mine, n))
        check(abs(drops - n) <= 3, "%d of %d altered keyed frames were not dropped" % (n - drops, n))
        check(dl["updates_applied"] == 0, "an altered keyed frame was applied")
        d.assert_healthy("keyed")
        check(c.value("42.var.keyed") == ("int", "1"), "the keyed value is still there")
        return {"frames": n, "dropped": drops}
    finally:
        d.stop()


def unicast(binary, seed, log, long=False):
    """`--transport unicast`: frames from an address that is not a `--peer` are refused
    and counted, every one, mutated or not; the peer's own are read."""
    rng = seeded(seed, "unicast")
    peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    peer.bind(("127.0.0.1", 0))
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.bind(("127.0.0.1", 0))
    port = free_port(socket.SOCK_DGRAM)
    d = Daemon(binary, 1, ["--transport", "unicast", "--port", str(port), "--team", str(TEAM),
                           "--peer", "127.0.0.1:%d" % peer.getsockname()[1]])
    try:
        c = d.client()
        n = 20_000 if long else 2_000
        before = c.stats(["unicast_refused", "frames_in"])
        kernel0 = d.udp_drops()
        for i in range(n):
            data = rng.choice(base_frames(rng))
            if rng.random() < 0.5:
                data = mutate(rng, data)
            stranger.sendto(data, ("127.0.0.1", port))
            if i % 100 == 99:
                time.sleep(0.01)
        good = w.frame(TEAM, 3, rng.getrandbits(62) | 1, 1, [w.update("from_peer", 5)])
        peer.sendto(good, ("127.0.0.1", port))
        c.wait_for("3.var.from_peer", lambda v: v == ("int", "5"), 3.0)
        time.sleep(0.35)
        after = c.stats(["unicast_refused", "frames_in"])
        refused = after["unicast_refused"] - before["unicast_refused"]
        kernel = d.udp_drops() - kernel0
        log("  %d frames from a stranger: %d refused (+%d dropped by the kernel); the peer's frame read"
            % (n, refused, kernel))
        check(refused + kernel == n, "%d refused + %d kernel drops of %d" % (refused, kernel, n))
        d.assert_healthy("unicast")
        return {"frames": n, "refused": refused}
    finally:
        peer.close()
        stranger.close()
        d.stop()
