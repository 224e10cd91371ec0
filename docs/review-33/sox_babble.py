#!/usr/bin/env python3
"""Independent check of #33, written outside the project with other tools (lead, 14th session).

The issue's first outside test, rebuilt: a hall made by sox (`reverb`, a band limit, a sender clock
error), babble of espeak-ng voices with their pauses kept as digital silence, no added floor.
Messages come from `huddle audio encode` and are decoded by `huddle audio decode --json`; nothing of
the project's room harness is used.

SNR: the message's in-band (500-4000 Hz) power while it sounds, over the babble's in-band power
averaged over the whole track *including its pauses* (so its bursts are louder than the stated SNR).

usage: sox_babble.py HUDDLE SEED OUTDIR [--per 20]
"""
import json, os, random, subprocess, sys
import numpy as np
from scipy import signal
from scipy.io import wavfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from wavtools import RATE, read, run  # noqa: E402

HUDDLE, SEED, OUT = sys.argv[1], int(sys.argv[2]), sys.argv[3]
PER = int(sys.argv[5]) if len(sys.argv) > 5 and sys.argv[4] == "--per" else 20
REVERBS = [0, 30, 50, 70, 90]
# VARY=1: each hall's damping and room scale drawn, clock errors 0.1-0.5%, a microphone tilt.
VARY = os.environ.get("VARY") == "1"
# OVERLAP=1: every message has a second robot's message begun 0-1.5 s from it (another sender).
OVERLAP = os.environ.get("OVERLAP") == "1"
SNRS = [20, 10, 0, -6]
os.makedirs(OUT, exist_ok=True)
rng = random.Random(SEED)
WORDS = ("ball goal robot kick pass left right keeper striker defender field line penalty whistle "
         "corner throw half time referee team play game score fast slow turn walk stand fall up down "
         "the a and but then now here there look go stop wait yes no good bad one two three four five").split()
VOICES = ["en", "en-us", "en-gb-scotland", "en-gb-x-rp", "en-029", "en+f3", "en-us+f2", "en+m4"]
BAND = signal.butter(8, [500, 4000], btype="bandpass", fs=RATE, output="sos")


def write(path, x):
    wavfile.write(path, RATE, x.astype(np.float32))


def utterance(i, voice):
    text = " ".join(rng.choice(WORDS) for _ in range(rng.randint(3, 12)))
    raw, wav = f"{OUT}/u{i}.raw.wav", f"{OUT}/u{i}.wav"
    run(["espeak-ng", "-v", voice, "-s", str(rng.randint(130, 200)), "-p", str(rng.randint(20, 80)), "-w", raw, text])
    run(["sox", raw, "-r", str(RATE), "-b", "32", "-e", "floating-point", wav])
    x = read(wav)
    os.remove(raw); os.remove(wav)
    return x


def babble(length, talkers):
    """Talkers speaking sentences with pauses of digital silence between them."""
    out = np.zeros(length)
    k = 0
    for t in range(talkers):
        voice = rng.choice(VOICES)
        gain = 10 ** (rng.uniform(-6, 6) / 20)
        pos = int(rng.uniform(0, 3) * RATE)
        while pos < length:
            u = utterance(k, voice); k += 1
            n = min(len(u), length - pos)
            out[pos:pos + n] += gain * u[:n]
            pos += n + int(rng.uniform(0.3, 3.0) * RATE)
    return out


def hall(x, reverb, speed, tag):
    src, dst = f"{OUT}/{tag}-in.wav", f"{OUT}/{tag}-out.wav"
    write(src, x)
    chain = []
    if speed != 1.0:
        chain += ["speed", f"{speed:.4f}", "rate", str(RATE)]
    if reverb > 0:
        damp, scale = (rng.randint(10, 90), rng.randint(40, 100)) if VARY else (50, 100)
        chain += ["reverb", str(reverb), str(damp), str(scale)]
    chain += ["sinc", "150-7000"]
    if VARY:
        chain += ["equalizer", str(rng.choice([700, 1200, 2500])), "1q", str(rng.choice([-6, 6]))]
    run(["sox", src, "-b", "32", "-e", "floating-point", dst] + chain)
    y = read(dst)
    os.remove(src); os.remove(dst)
    return y[: len(x)] if len(y) >= len(x) else np.pad(y, (0, len(x) - len(y)))


def inband_power(x):
    return float(np.mean(signal.sosfilt(BAND, x) ** 2))


def main():
    rows = []
    plan = []  # (kind, sender, value)
    for cond_i, (rv, snr) in enumerate([(r, s) for r in REVERBS for s in SNRS]):
        msgs, track_len = [], int((6 + 5 * PER) * RATE)
        tx = np.zeros(track_len)
        for m in range(PER):
            sender = rng.randrange(3)
            if rng.random() < 0.6:
                kind, value, args = "short", rng.randrange(10), ["--data"]
            else:
                kind, value, args = "long", rng.randrange(121), ["--long"]
            path = f"{OUT}/msg.wav"
            run([HUDDLE, "audio", "encode", "--team", "checked", "--sender", str(sender), args[0], str(value), path])
            x = read(path)
            at = int((3 + 5 * m + rng.uniform(0, 1.0)) * RATE)
            tx[at:at + len(x)] += 0.3 * x
            msgs.append((at / RATE, len(x) / RATE, kind, sender, value))
            if OVERLAP:
                other = rng.choice([s for s in range(3) if s != sender])
                if rng.random() < 0.6:
                    k2, v2, a2 = "short", rng.randrange(10), "--data"
                else:
                    k2, v2, a2 = "long", rng.randrange(121), "--long"
                run([HUDDLE, "audio", "encode", "--team", "checked", "--sender", str(other), a2, str(v2), path])
                y = read(path) * 10 ** (rng.uniform(-6, 6) / 20)
                at2 = at + int(rng.uniform(-1.5, 1.5) * RATE)
                tx[at2:at2 + len(y)] += 0.3 * y
                msgs.append((at2 / RATE, len(y) / RATE, k2, other, v2))
        speed = 1.0 + rng.choice([-1, 1]) * (rng.uniform(0.001, 0.005) if VARY else 0.004)
        tx_h = hall(tx, rv, speed, "tx")
        bab_h = hall(babble(track_len, rng.randint(2, 4)), rv, 1.0, "bab")
        on = np.zeros(track_len, bool)
        for (t0, d, *_rest) in msgs:
            a = int(t0 / speed * RATE); on[a:a + int(d / speed * RATE)] = True
        p_msg = float(np.mean(signal.sosfilt(BAND, tx_h)[on] ** 2))
        p_bab = inband_power(bab_h)
        g = np.sqrt(p_msg / (p_bab * 10 ** (snr / 10)))
        mix = tx_h + g * bab_h
        mix *= 0.5 / max(1e-9, np.max(np.abs(mix)))
        path = f"{OUT}/mix-{SEED}-{rv}-{snr}.wav"
        write(path, mix)
        res = subprocess.run([HUDDLE, "audio", "decode", "--team", "checked", "--json", path], capture_output=True, text=True)
        dec = [json.loads(l) for l in res.stdout.splitlines() if l.startswith("{")]
        if os.environ.get("KEEP") != f"{rv},{snr}":
            os.remove(path)
        right = {"short": 0, "long": 0}; sent = {"short": 0, "long": 0}; wrong = 0; used = set()
        for (t0, d, kind, sender, value) in msgs:
            sent[kind] += 1
            a, b = t0 / speed - 0.6, (t0 + d) / speed + 0.6
            hits = [i for i, x in enumerate(dec) if a <= x["t"] <= b]
            used.update(hits)
            ok = any(dec[i]["kind"] == kind and dec[i]["sender"] == sender and dec[i]["data"] == value for i in hits)
            right[kind] += ok
        # A decode is wrong when it is near a sent message and equals none of the messages near it.
        for i, x in enumerate(dec):
            near = [mm for mm in msgs if mm[0] / speed - 0.6 <= x["t"] <= (mm[0] + mm[1]) / speed + 0.6]
            if near and not any(x["kind"] == k and x["sender"] == se and x["data"] == v for (_, _, k, se, v) in near):
                wrong += 1
                print(f"WRONG reverb {rv} snr {snr}: decoded {x} near {[(round(t0 / speed, 2), k, se, v) for (t0, _, k, se, v) in near]}", file=sys.stderr)
        false = len(dec) - len(used)
        row = dict(seed=SEED, reverb=rv, snr=snr, short=f"{right['short']}/{sent['short']}", long=f"{right['long']}/{sent['long']}",
                   wrong=wrong, false=false, right=right["short"] + right["long"], sent=len(msgs))
        print(json.dumps(row), flush=True)
        rows.append(row)
    tot = sum(r["right"] for r in rows); n = sum(r["sent"] for r in rows)
    print(json.dumps(dict(seed=SEED, total=f"{tot}/{n}", wrong=sum(r["wrong"] for r in rows), false=sum(r["false"] for r in rows))))


main()
