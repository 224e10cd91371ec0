"""Attacks on the GameController listener (RGme v18 on a port of the run's own) and
checks of the RGrt status packets the daemon sends back.

RGme layout (GameController3's RoboCupGameControlData.h, 118 bytes, little-endian):
header "RGme", version, packetNumber, playersPerTeam, competitionPhase, competitionType,
gamePhase, state, setPlay, firstHalf, kickingTeam, secsRemaining (i16), secondaryTime
(i16), then two TeamInfo of 50 bytes: teamNumber, fieldPlayerColour, goalkeeperColour,
goalkeeper, score, penaltyShot, singleShots (u16), messageBudget (u16), 20 x (penalty,
secsTillUnpenalised). RGrt: "RGrt", version 4, playerNum, teamNum, fallen, 6 x f32.
"""

import math
import socket
import struct
import threading
import time

from harness import Daemon, check, free_port, scratch_group, seeded

TEAM = 12
OTHER = 34
GC_COUNTERS = ["accepted", "stale", "bad_length", "bad_header", "wrong_version",
               "bad_field", "wrong_team", "status_sent"]
STATES = ["initial", "ready", "set", "playing", "finished", "standby"]


def rgme(number, state=3, secs=600, secondary=0, budget=1200, phase=0, set_play=0,
         first_half=1, teams=(TEAM, OTHER), penalties=None, version=18, header=b"RGme"):
    b = header + bytes([version, number & 0xff, 5, 0, 0, phase, state, set_play, first_half, teams[0]])
    b += struct.pack("<hh", secs, secondary)
    for t in teams:
        players = bytearray(40)
        for p, (pen, left) in (penalties or {}).items() if t == TEAM else []:
            players[2 * (p - 1)], players[2 * (p - 1) + 1] = pen, left
        b += bytes([t, 0, 1, 1, 0, 0]) + struct.pack("<HH", 0, budget) + bytes(players)
    assert len(b) == 118
    return b


class Gc:
    """A scripted GC on 127.0.0.1 and the status packets it receives."""

    def __init__(self, to):
        self.to = to
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.status = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.status.bind(("127.0.0.1", 0))
        self.status.settimeout(0.2)
        self.status_port = self.status.getsockname()[1]
        self.received, self.bad = [], []
        self.running = True
        self.thread = threading.Thread(target=self._listen, daemon=True)
        self.thread.start()

    def send(self, data, pace=0.0):
        self.sock.sendto(data, self.to)
        if pace:
            time.sleep(pace)

    def _listen(self):
        while self.running:
            try:
                data, _ = self.status.recvfrom(2048)
            except socket.timeout:
                continue
            except OSError:
                return
            why = check_rgrt(data)
            (self.bad if why else self.received).append(why or data)

    def stop(self):
        self.running = False
        self.thread.join()
        self.sock.close()
        self.status.close()


def check_rgrt(data):
    """Why `data` is not a status packet GameController3 takes (None: it is)."""
    if len(data) != 32:
        return "length %d" % len(data)
    if data[:4] != b"RGrt" or data[4] != 4:
        return "header %r" % data[:5]
    if not 1 <= data[5] <= 20 or data[6] != TEAM or data[7] not in (0, 1):
        return "player %d team %d fallen %d" % (data[5], data[6], data[7])
    floats = struct.unpack("<6f", data[8:])
    if any(math.isnan(f) for f in floats):
        return "NaN in %r" % (floats,)
    return None


def start(binary, rng, extra=()):
    group, port = scratch_group(rng)
    gc_port = free_port(socket.SOCK_DGRAM)
    gc = Gc(("127.0.0.1", gc_port))
    d = Daemon(binary, 1, ["--group", "%s:%d" % (group, port), "--team", str(TEAM)],
               ["--budget", "spl", "--gc-listen", "127.0.0.1:%d" % gc_port,
                "--gc-status-port", str(gc.status_port)] + list(extra))
    return d, gc


def gc_stats(c):
    time.sleep(0.15)
    return {k: c.stat("gc." + k) for k in GC_COUNTERS}


def packets(binary, seed, log, long=False):
    """Every length 0-200, wrong headers, versions, fields and teams: each counted under
    its reason, the game unmoved; then a valid one moves it."""
    rng = seeded(seed, "gc_packets")
    d, gc = start(binary, rng)
    try:
        c = d.client()
        n = 1
        gc.send(rgme(n, state=3, secs=500))
        c.wait_for("local.var.gc.secs_remaining", lambda v: v == ("int", "500"))
        before = gc_stats(c)
        kernel0 = d.udp_drops()
        want = dict.fromkeys(GC_COUNTERS, 0)
        good = rgme(n + 1, state=4, secs=1)
        send, sent = gc.send, [0]

        def paced(data):
            # The socket's buffer holds ~200 of these: a pause every 40 lets a busy
            # daemon (a debug build on a loaded CI machine) read them all.
            send(data, 0.0005)
            sent[0] += 1
            if sent[0] % 40 == 0:
                time.sleep(0.05)
        gc.send = paced
        for length in range(0, 201):
            if length == 118:
                continue
            pad = bytes(rng.randrange(256) for _ in range(max(0, length - 118)))
            gc.send((good + pad)[:length])
            want["bad_length"] += 1
        for _ in range(20):
            h = bytes(rng.randrange(256) for _ in range(4))
            if h != b"RGme":
                gc.send(rgme(n + 1, state=4, header=h))
                want["bad_header"] += 1
        for v in range(256):
            if v != 18:
                gc.send(rgme(n + 1, state=4, version=v))
                want["wrong_version"] += 1
        fields = [(9, range(4, 256)), (10, range(6, 256)), (11, range(6, 256)), (12, range(2, 256))]
        for offset, values in fields:
            for v in rng.sample(list(values), 20 if not long else len(values)):
                b = bytearray(good)
                b[offset] = v
                gc.send(bytes(b))
                want["bad_field"] += 1
        for teams in [(1, 2), (OTHER, 99), (0, 0), (255, 255), (TEAM + 1, TEAM - 1)]:
            gc.send(rgme(n + 1, state=4, teams=teams))
            want["wrong_team"] += 1
        gc.send = send
        time.sleep(0.3)
        d_ = {k: v - before[k] for k, v in gc_stats(c).items()}
        kernel = d.udp_drops() - kernel0
        log("  bad packets: %s; %d dropped by the kernel" % (", ".join("%s %d" % (k, v) for k, v in d_.items() if v), kernel))
        if kernel:
            # Which reason a dropped packet would have had is unknown: the total holds.
            total = sum(d_[k] for k in want if k != "status_sent")
            check(total + kernel == sum(want.values()), "%d counted + %d kernel drops, %d sent"
                  % (total, kernel, sum(want.values())))
            check(d_["accepted"] == 0, "a bad packet was accepted")
        else:
            for k in ["bad_length", "bad_header", "wrong_version", "bad_field", "wrong_team", "accepted", "stale"]:
                check(d_[k] == want[k], "gc.%s moved by %d, expected %d" % (k, d_[k], want[k]))
        check(c.value("local.var.gc.state") == ("string", '"playing"'), "a bad packet moved the game")
        check(c.value("local.var.gc.secs_remaining") == ("int", "500"), "a bad packet moved the clock")
        # Extremes a valid packet may carry: the clock past its end, budgets 0 and 65535.
        n += 1
        for secs, secondary, budget in [(-1, -1, 0), (-32768, 32767, 65535), (32767, -32768, 1),
                                        (0, 0, 0), (-300, 0, 65535)]:
            gc.send(rgme(n, state=3, secs=secs, secondary=secondary, budget=budget))
            c.wait_for("local.var.gc.secs_remaining", lambda v, s=secs: v == ("int", str(s)))
            c.wait_for("local.var.gc.budget", lambda v, b=budget: v == ("int", str(b)))
            n += 1
        # A penalty for every player, every code.
        gc.send(rgme(n, penalties={p: (rng.randrange(256), rng.randrange(256)) for p in range(1, 21)}))
        c.wait_for("local.var.gc.penalized", lambda v: v[0] == "floats")
        d.assert_healthy("gc packets")
        check(not gc.bad, "bad status packets: %r" % gc.bad[:3])
        return {"bad_packets": sum(want.values())}
    finally:
        gc.stop()
        d.stop()


def newer(last, number):
    """The docs' rule: up to 127 ahead of the newest accepted is newer; a 0 more than
    16 behind is a restarted GC."""
    ahead = (number - last) % 256
    return 1 <= ahead <= 127 or (number == 0 and 128 <= ahead <= 239)


def order(binary, seed, log, long=False):
    """Packet numbers forwards, backwards, repeated and wrapping at 255, as a lossy WLAN
    and a hostile one deliver them: the game the daemon shows is always the newest
    accepted one, never an older one."""
    rng = seeded(seed, "gc_order")
    d, gc = start(binary, rng)
    try:
        c = d.client()
        last = rng.randrange(256)
        clock = 600
        gc.send(rgme(last, secs=clock))
        c.wait_for("local.var.gc.secs_remaining", lambda v: v == ("int", str(clock)))
        steps = 400 if long else 120
        accepted = stale = 0
        shown, shown_state = clock, 3
        before = gc_stats(c)
        for i in range(steps):
            r = rng.random()
            if r < 0.5:
                number = (last + rng.randint(1, 3)) % 256
            elif r < 0.7:
                number = (last - rng.randint(0, 40)) % 256
            elif r < 0.8:
                number = (last + 128 + rng.randint(0, 127)) % 256
            elif r < 0.9:
                number = 0
            else:
                number = rng.randrange(256)
            clock -= 1
            state = rng.randrange(6)
            gc.send(rgme(number, state=state, secs=clock))
            if newer(last, number):
                last, shown, shown_state = number, clock, state
                accepted += 1
            else:
                stale += 1
            want = shown
            got = c.wait_for("local.var.gc.secs_remaining", lambda v: v == ("int", str(want)), 2.0)
            check(got == ("int", str(want)), "after packet %d" % number)
            st = c.value("local.var.gc.state")
            check(st == ("string", '"%s"' % STATES[shown_state]),
                  "packet %d: state %r, the newest accepted said %s" % (number, st, STATES[shown_state]))
        d_ = {k: v - before[k] for k, v in gc_stats(c).items()}
        log("  %d packets out of order: accepted %d (expected %d), stale %d (expected %d), wrapped past 255"
            % (steps, d_["accepted"], accepted, d_["stale"], stale))
        check((d_["accepted"], d_["stale"]) == (accepted, stale), "the counts differ from the rule")
        d.assert_healthy("gc order")
        return {"packets": steps, "accepted": accepted, "stale": stale}
    finally:
        gc.stop()
        d.stop()


def flood(binary, seed, log, long=False):
    """A flood of valid and invalid packets while the program writes: the daemon keeps
    answering, every packet it read is counted once, status packets stay valid."""
    rng = seeded(seed, "gc_flood")
    d, gc = start(binary, rng)
    try:
        c = d.client()
        for line in ["SETV local.var.robot.pose [1e300, -1e300, 7.0, 0.01, 0, 0, 0.01, 0, 0.003]",
                     "SETV local.var.robot.pose [4.5, -3.0, 3.14, 0.01, 0, 0, 0.01, 0, 0.003]",
                     "SETV local.var.robot.fallen true"]:
            c.ask(line)
        # The team ball the status packets carry is the team layer's: a program cannot
        # write it, NaN or not.
        for line in ["SETV local.var.team.ball [NaN, inf]", "SETV local.var.team.ball [1e39, -1e39]"]:
            a = c.ask(line)
            check(a.startswith("ERR 423 "), "%s: %r (the team layer's key)" % (line, a))
        n = 60_000 if long else 6_000
        before = gc_stats(c)
        kernel0 = d.udp_drops()
        sent_good = 0
        number = 0
        t0 = time.monotonic()
        for i in range(n):
            r = rng.random()
            if r < 0.5:
                number = (number + 1) % 256
                gc.send(rgme(number, state=rng.randrange(6), secs=rng.randint(-32768, 32767),
                             budget=rng.randrange(65536)))
                sent_good += 1
            else:
                b = bytearray(rgme(rng.randrange(256)))
                for _ in range(rng.randint(1, 6)):
                    b[rng.randrange(len(b))] = rng.randrange(256)
                if rng.random() < 0.3:
                    b = b[:rng.randrange(len(b) + 1)] + bytes(rng.randrange(256) for _ in range(rng.randint(0, 40)))
                gc.send(bytes(b))
            if i % 200 == 199:
                check(c.ask("SETV *.var.x %d" % i) == "OK", "the relay stopped answering in the flood")
        secs = time.monotonic() - t0
        time.sleep(1.5)  # status packets for a while
        after = gc_stats(c)
        d_ = {k: v - before[k] for k, v in after.items()}
        counted = sum(v for k, v in d_.items() if k != "status_sent")
        kernel = d.udp_drops() - kernel0
        log("  %d packets in %.1f s: counted %d, kernel dropped %d (%s), %d status packets, all valid"
            % (n, secs, counted, kernel, ", ".join("%s %d" % (k, v) for k, v in d_.items() if v), len(gc.received)))
        check(counted + kernel == n, "%d counted + %d dropped by the kernel, %d sent" % (counted, kernel, n))
        check(counted >= 0.5 * n, "only %d of %d packets counted" % (counted, n))
        check(not gc.bad, "bad status packets: %r" % gc.bad[:3])
        check(len(gc.received) > 0, "no status packets")
        d.assert_healthy("gc flood")
        return {"packets": n, "counted": counted, "status": len(gc.received)}
    finally:
        gc.stop()
        d.stop()


def broadcast(binary, seed, log, long=False):
    """The GC's way: broadcast (to 127.255.255.255 only) to a daemon listening on every
    address of a port of the run's own; its status goes back to 127.0.0.1."""
    rng = seeded(seed, "gc_broadcast")
    group, port = scratch_group(rng)
    gc_port = free_port(socket.SOCK_DGRAM)
    gc = Gc(("127.255.255.255", gc_port))
    gc.sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
    d = Daemon(binary, 1, ["--group", "%s:%d" % (group, port), "--team", str(TEAM)],
               ["--budget", "spl", "--gc-listen", "0.0.0.0:%d" % gc_port,
                "--gc-status-port", str(gc.status_port)])
    try:
        c = d.client()
        for i in range(1, 8):
            gc.send(rgme(i, secs=600 - i))
            time.sleep(0.1)
        c.wait_for("local.var.gc.secs_remaining", lambda v: v == ("int", "593"))
        deadline = time.monotonic() + 3
        while not gc.received and time.monotonic() < deadline:
            time.sleep(0.1)
        check(gc.received, "no status packet came back")
        check(not gc.bad, "bad status packets: %r" % gc.bad[:3])
        log("  7 broadcasts heard, %d status packets back" % len(gc.received))
        d.assert_healthy("gc broadcast")
        return {"status": len(gc.received)}
    finally:
        gc.stop()
        d.stop()
