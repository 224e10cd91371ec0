"""Attacks on the team layer's inputs: a program's senses with extreme (finite, valid
shaped) values over the relay, and a spoofed teammate whose world models and claims are
mutated copies of a real one's. The layer's outputs must stay finite and it must keep
ticking."""

import math
import time

import hwire as w
from harness import Daemon, ROBOT_POSE, check, multicast_sender, scratch_group, seeded, team_net

TEAM = 7
EXTREMES = [0.0, -0.0, 1e-300, -1e-300, 5e-324, 1e300, -1e300, 1.7e308, -1.7e308, 1e15, -1e15,
            1e-9, 3.14159, 1e6, -1e6, 2.0 ** 53, 100.0, -100.0]
OUTPUTS = ["local.var.team.ball", "local.var.team.pose", "local.var.team.mates",
           "local.var.team.own_ball", "local.var.team.cost"]


def floats(vals):
    return "[" + ", ".join(repr(float(v)) for v in vals) + "]"


def sense_line(rng):
    """One write of a program's senses, extreme values in the documented shapes."""
    x = lambda: rng.choice(EXTREMES) if rng.random() < 0.5 else rng.uniform(-5, 5)  # noqa: E731
    var = lambda: rng.choice([1e-300, 5e-324, 1e-12, 1e300, 1e-3, 0.01, 1.0, 1e6])  # noqa: E731
    kind = rng.randrange(7)
    if kind == 0:
        v, c = var(), var()
        # Sometimes all but singular: a correlation a hair below 1.
        off = math.sqrt(v * c) * (1 - 1e-12) if rng.random() < 0.2 else 0.0
        cov = [v, off, 0.0, c, 0.0, rng.choice([var(), 0.003])]
        return "SETV local.var.robot.pose %s" % floats([x(), x(), x()] + cov + ([rng.choice([0.0, 0.5, 9.9])] if rng.random() < 0.3 else []))
    if kind == 1:
        return "SETV local.var.robot.odometry %s" % floats([x(), x(), x()])
    if kind == 2:
        a, b = var(), var()
        off = math.sqrt(a * b) * (1 - 1e-12) if rng.random() < 0.2 else 0.0
        return "SETV local.var.robot.ball %s" % floats([x(), x(), a, off, b])
    if kind == 3:
        n = rng.randint(1, 4)
        return "SETV local.var.robot.landmarks %s" % floats(
            sum(([x(), x(), abs(x()), x(), var(), var()] for _ in range(n)), []))
    if kind == 4:
        return "SETV local.var.robot.kick %s" % floats([x(), x()] + ([rng.random()] if rng.random() < 0.5 else []))
    if kind == 5:
        return "SETV local.var.robot.cost %r" % float(x())
    return rng.choice(["SETV local.var.robot.ball_reset true", "SETV local.var.robot.goalkeeper %s" % rng.choice(["true", "false"]),
                       "SETV local.var.robot.goal_in_view true"])


def finite_outputs(c, what):
    for key in OUTPUTS:
        v = c.value(key)
        if v is None:
            continue
        text = v[1].lower()
        check("nan" not in text and "inf" not in text, "%s: %s = %s" % (what, key, v[1][:200]))


def mutate_lwm(rng, lwm):
    b = bytearray(lwm)
    for _ in range(rng.randint(1, 6)):
        r = rng.random()
        i = rng.randrange(len(b))
        if r < 0.4:
            b[i] ^= 1 << rng.randrange(8)
        elif r < 0.7:
            b[i] = rng.choice([0, 0xff, 0x7f, 0x80])
        else:
            j = rng.randrange(0, len(b) - 1)
            b[j:j + 2] = rng.choice([b"\xff\x7f", b"\x00\x80", b"\xff\xff", b"\x00\x00"])
    return bytes(b)


def inputs(binary, seed, log, long=False):
    """Robots 1 and 2 with their team layers; robot 1's program writes extreme senses,
    a spoofed robot 3 sends mutated world models and claims. Both keep ticking, their
    outputs stay finite, and robot 2 still hears robot 1."""
    rng = seeded(seed, "team")
    group, port = scratch_group(rng)
    net = team_net(group, port, TEAM)
    d1, d2 = Daemon(binary, 1, net), Daemon(binary, 2, net)
    sock = multicast_sender()
    try:
        c1, c2 = d1.client(), d2.client()
        pose = ROBOT_POSE
        for c in (c1, c2):
            check(c.ask("SETV local.var.robot.pose %s" % pose) == "OK", "pose")
            check(c.ask("SETV local.var.robot.ball [1.0, 0.5, 0.01, 0.0, 0.01]") == "OK", "ball")
            check(c.ask("SETV local.var.robot.pose %s" % pose) == "OK", "pose")
        world = c1.wait_for("local.var.team.world", lambda v: v[0] == "bytes", 5.0)
        lwm = bytes.fromhex(world[1][2:])
        c2.wait_for("1.var.world.local", lambda v: v[0] == "bytes", 5.0)
        n = 20_000 if long else 1_500
        answers = {}
        incarnation = rng.getrandbits(62) | 1
        tick0 = int(c1.value("local.var.team.tick")[1])
        # First robot 1's program alone, then the spoofed teammate alone: a non-finite
        # output then says which input made it.
        for i in range(n):
            line = sense_line(rng)
            a = c1.ask(line)
            answers[a[:7]] = answers.get(a[:7], 0) + 1
            check(a.startswith(("OK", "ERR 412")), "%s answered %s" % (line[:100], a))
            if i % 50 == 49:
                finite_outputs(c1, "after %d writes of extreme senses" % (i + 1))
        check(c1.ask("SETV local.var.robot.pose %s" % pose) == "OK", "pose")
        for i in range(n):
            h = rng.choice(EXTREMES + [rng.uniform(0, 10)])
            items = [w.item4(w.ITEM_KNOWN, w.known_fields(1, mutate_lwm(rng, lwm), i + 1, rng.randrange(10 ** 6))),
                     w.item4(w.ITEM_KNOWN, w.known_fields(0, [h, rng.choice([0.0, 1.0, 0.5, -1.0])], i + 1, 0))]
            sock.sendto(w.frame(TEAM, 3, incarnation, i + 1, items, stamp=rng.getrandbits(32)), (group, port))
            if i % 20 == 19:
                c2.ask("SETV local.var.robot.pose %s" % pose)
                time.sleep(0.002)
            if i % 100 == 99:
                for c in (c1, c2):
                    finite_outputs(c, "after %d spoofed world models" % (i + 1))
        # Sane senses again: the layer recovers and keeps ticking.
        for c in (c1, c2):
            check(c.ask("SETV local.var.robot.pose %s" % pose) == "OK", "pose after")
        tick1 = int(c1.value("local.var.team.tick")[1])
        finite_outputs(c1, "at the end")
        finite_outputs(c2, "at the end")
        check(tick1 > tick0, "robot 1's layer stopped ticking")
        check(c1.ask("SETV *.var.after 1") == "OK", "set")
        c2.wait_for("1.var.after", lambda v: v == ("int", "1"), 5.0)
        goer = c2.value("local.var.team.goer")
        log("  %d extreme sense writes (%s), %d mutated world models and claims from a spoofed robot 3; "
            "%d ticks; outputs finite; goer %s" % (n, ", ".join("%s %d" % kv for kv in sorted(answers.items())), n,
                                                  tick1 - tick0, goer[1] if goer else None))
        for d in (d1, d2):
            d.assert_healthy("team inputs")
        return {"writes": n, "ticks": tick1 - tick0}
    finally:
        d1.stop()
        d2.stop()

