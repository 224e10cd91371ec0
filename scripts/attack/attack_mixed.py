"""A mixed-version team on loopback, and frames of a newer build made up from the docs."""

import time

import hwire as w
from harness import Daemon, ROBOT_POSE, check, multicast_sender, scratch_group, seeded, team_net

TEAM = 7
VALUES = [("i", "int", "-42", -42), ("f", "float", "2.5", 2.5), ("b", "bool", "true", True),
          ("s", "string", '"hello \\"team\\""', 'hello "team"'), ("v", "floats", "[1.0, -2.5]", [1.0, -2.5]),
          ("y", "bytes", "0x0a0b", b"\x0a\x0b")]


def future_frame(rng, sender, incarnation, seq, version=w.VERSION):
    """A frame of a made-up newer build: every value type this build knows, between
    items it does not (a new item type, a new value tag, a known-path index beyond the
    table) and known items with a field appended. (frame, unknown items)."""
    items = []
    unknown = 0
    for path, _, _, v in VALUES:
        items.append(w.item4(w.ITEM_UPDATE, w.update_fields("fut." + path, v, seq, 0) +
                             (b"\x07new" if rng.random() < 0.5 else b"")))
        r = rng.random()
        if r < 0.4:
            items.append(w.item4(rng.randint(5, 1000), bytes(rng.randrange(256) for _ in range(rng.randint(0, 20)))))
        elif r < 0.7:
            items.append(w.item4(0, w.string("fut.tag") + bytes([rng.randint(6, 255)]) + b"\x01\x02\x01\x00"))
        else:
            items.append(w.item4(4, w.known_fields(rng.randint(4, 200), 1)))
        unknown += 1
    rng.shuffle(items)
    return w.frame(TEAM, sender, incarnation, seq, items, stamp=rng.getrandbits(32)), unknown


def counters(c):
    time.sleep(0.35)
    return {k: c.stat(k) for k in ["items_skipped", "drops.malformed", "drops.unknown_version", "frames_in"]}


def future_items(binary, seed, log, long=False):
    """Two robots of this build hear a newer build's robot 9: every key they know is
    read, every item they do not is skipped and counted, no frame dropped."""
    rng = seeded(seed, "future")
    group, port = scratch_group(rng)
    net = team_net(group, port, TEAM)
    d1, d2 = Daemon(binary, 1, net), Daemon(binary, 2, net)
    sock = multicast_sender()
    try:
        c1, c2 = d1.client(), d2.client()
        before = [counters(c1), counters(c2)]
        n = 500 if long else 40
        incarnation = rng.getrandbits(62) | 1
        skipped = 0
        for seq in range(1, n + 1):
            f, unknown = future_frame(rng, 9, incarnation, seq)
            sock.sendto(f, (group, port))
            skipped += unknown
            time.sleep(0.005)
        for c, b in zip((c1, c2), before):
            for path, ty, text, _ in VALUES:
                c.wait_for("9.var.fut." + path, lambda v, ty=ty, text=text: v == (ty, text), 3.0)
            d = {k: v - b[k] for k, v in counters(c).items()}
            check(d["items_skipped"] == skipped, "items skipped %d, the frames held %d" % (d["items_skipped"], skipped))
            check(d["drops.malformed"] == 0, "%d newer frames dropped as malformed" % d["drops.malformed"])
        log("  %d frames of a newer build: every known key read by both, %d unknown items skipped and counted, 0 dropped"
            % (n, skipped))
        for d in (d1, d2):
            d.assert_healthy("future items")
        return {"frames": n, "skipped": skipped}
    finally:
        d1.stop()
        d2.stop()


def mixed_team(binary, old, seed, log, long=False):
    """Robot 1 of this build and robot 2 of an older one replicate every key both know
    (all six value types, talk, the team layer's keys) both ways; then both hear a newer
    build's frames, and what the older one does with them is reported."""
    rng = seeded(seed, "mixed")
    group, port = scratch_group(rng)
    net = team_net(group, port, TEAM)
    new, older = Daemon(binary, 1, net), Daemon(old, 2, net)
    sock = multicast_sender()
    try:
        cn, co = new.client(), older.client()
        watch_n, watch_o = new.client(), older.client()
        for c in (watch_n, watch_o):
            check(c.ask("ADDW +.talk.plan") == "OK", "watch talk")
        pose = ROBOT_POSE
        for me, c in ((1, cn), (2, co)):
            for path, _, text, _ in VALUES:
                check(c.ask("SETV *.var.mix.%s %s" % (path, text)) == "OK", "robot %d sets %s" % (me, path))
            check(c.ask("SETV local.var.robot.pose %s" % pose) == "OK", "robot %d's pose" % me)
            check(c.ask("SETV local.var.robot.cost %d.5" % me) == "OK", "robot %d's cost" % me)
        for mine, theirs, other in ((cn, co, 1), (co, cn, 2)):
            for path, ty, text, _ in VALUES:
                theirs.wait_for("%d.var.mix.%s" % (other, path), lambda v, ty=ty, text=text: v == (ty, text), 5.0)
        # The team layer's keys, where the older build runs one in its daemon.
        time.sleep(1.0)
        old_layer = co.value("2.var.machine.heuristic") is not None
        layer_keys = ["machine.heuristic", "world.local"]
        pairs = ((cn, 2), (co, 1)) if old_layer else ((co, 1),)
        for c, other in pairs:
            for path in layer_keys:
                c.wait_for("%d.var.%s" % (other, path), lambda v: v[0] in ("floats", "bytes"), 5.0)
        for i in range(5):
            check(cn.ask("SETV *.talk.plan %d" % i) == "OK", "talk")
            check(co.ask("SETV *.talk.plan %d" % (10 + i)) == "OK", "talk")
        got_o = [watch_o.line() for _ in range(5)]
        got_n = [watch_n.line() for _ in range(5)]
        check(got_o == ["UPD 1.talk.plan int %d 0" % i for i in range(5)], "old robot heard %r" % got_o)
        check(got_n == ["UPD 2.talk.plan int %d 0" % (10 + i) for i in range(5)], "new robot heard %r" % got_n)
        goer_n = cn.wait_for("local.var.team.goer", lambda v: v == ("int", "1"), 5.0)
        goer_o = co.wait_for("local.var.team.goer", lambda v: v == ("int", "1"), 5.0) if old_layer \
            else ("", "none: no team layer in its daemon")
        drops = {}
        for name, c in (("this build", cn), ("older", co)):
            drops[name] = {k: c.stat("drops." + k) for k in ["malformed", "unknown_version"]}
            check(drops[name]["malformed"] == 0, "%s dropped %d of its teammate's frames as malformed"
                  % (name, drops[name]["malformed"]))
        log("  both ways: 6 value types, 5 talk messages each, claims and world models; one goer (%s, %s); "
            "drops %r" % (goer_n[1], goer_o[1], drops))
        # A newer build's frames: this build reads them minus the unknown items.
        before = [counters(cn), counters(co)]
        n, skipped = 20, 0
        incarnation = rng.getrandbits(62) | 1
        for seq in range(1, n + 1):
            f, unknown = future_frame(rng, 9, incarnation, seq)
            sock.sendto(f, (group, port))
            skipped += unknown
            time.sleep(0.005)
        for path, ty, text, _ in VALUES:
            cn.wait_for("9.var.fut." + path, lambda v, ty=ty, text=text: v == (ty, text), 3.0)
        dn = {k: v - before[0][k] for k, v in counters(cn).items()}
        do = {k: v - before[1][k] for k, v in counters(co).items()}
        read_old = sum(1 for path, ty, text, _ in VALUES if co.value("9.var.fut." + path) == (ty, text))
        check(dn["items_skipped"] == skipped and dn["drops.malformed"] == 0,
              "this build: %r for %d unknown items" % (dn, skipped))
        log("  %d newer frames (%d unknown items): this build skipped %d, malformed %d; the older build: "
            "read %d of 6 keys, skipped %d, malformed %d, unknown version %d"
            % (n, skipped, dn["items_skipped"], dn["drops.malformed"], read_old, do["items_skipped"],
               do["drops.malformed"], do["drops.unknown_version"]))
        for d in (new, older):
            d.assert_healthy("mixed team")
        return {"older_read_future_keys": read_old, "older_malformed": do["drops.malformed"],
                "older_skipped": do["items_skipped"], "older_unknown_version": do["drops.unknown_version"]}
    finally:
        new.stop()
        older.stop()
