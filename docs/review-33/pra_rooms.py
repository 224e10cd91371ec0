#!/usr/bin/env python3
"""Second independent check of #33, written outside the project (lead, fifteenth session).

Image-source + ray-traced rooms that the project's room set (`audio/rooms/make_rooms.py`, plain
shoeboxes with one flat absorption) does not have: an L-shaped lab and a five-walled hall,
extruded, with frequency-dependent wall absorption (bass lingers longer than treble, as in real
halls), scattering, air absorption and pyroomacoustics' hybrid ISM + ray tracing for the late
tail. Each room's absorption is scaled until the T30 measured on its own impulse responses is
within 12% of the nominal T60. Robots stand 1-8 m from the listening robot at 0.3-0.6 m, talkers
at 1.5-1.8 m; each sender has its own clock error (0.1-0.5%, either sign), applied by resampling.

Messages come from `huddle audio encode --team checked`, whole tracks are decoded by `huddle audio
decode --team checked --json`; nothing of the project's harness is used. Babble: 2-4 espeak-ng
talkers with their pauses kept as digital silence (no floor anywhere).

SNR: the messages' in-band (500-4000 Hz) power at the microphone while they sound, over the
babble's in-band power averaged over the whole track, pauses included. The three senders stand at
different distances, so each has its own SNR (rows give `sender_snr` and `dist`); `short_own0` and
`long_own0` count only the messages of senders whose own SNR is >= 0 dB. A message's *local* SNR
(seventeenth session) is its own in-band power over the babble's in-band power during that
message (its frames): babble that talks through a message and pauses elsewhere makes the local
SNR lower than the sender's average; `short_loc0`/`long_loc0` count messages whose local SNR is
>= 0 dB, and `loc_lost` lists the lost messages' local SNRs (one sender's rows only).

Scoring (per decoded line): right if it equals a message sounding within 0.6 s of it; wrong if it
is near sent messages and equals none of them; false if it is near none.

pyroomacoustics' ray tracer draws its rays from an unseeded generator, so the same seed gives
slightly different tails run to run (T30 within a few %): to compare decoders on the same audio,
give several binaries at once (HUDDLE may be `a,b`): every mix is decoded by each, rows say which.

usage: pra_rooms.py HUDDLE[,HUDDLE2...] SEED OUTDIR [--per 100]
       (one JSON line per condition and binary, then a total per binary; env FIRST/LAST pick rooms)
"""
import json, os, random, subprocess, sys
import numpy as np
import pyroomacoustics as pra
from scipy import signal
from scipy.io import wavfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from wavtools import RATE, read, run  # noqa: E402

HUDDLES, SEED, OUT = sys.argv[1].split(","), int(sys.argv[2]), sys.argv[3]
HUDDLE = HUDDLES[0]
PER = int(sys.argv[5]) if len(sys.argv) > 5 and sys.argv[4] == "--per" else 100
SPACING = 6.0  # s between message starts (a long message is 2 s, plus the tail of a 2 s room)
os.makedirs(OUT, exist_ok=True)
rng = random.Random(SEED)
BAND = signal.butter(8, [500, 4000], btype="bandpass", fs=RATE, output="sos")
FREQS = [125, 250, 500, 1000, 2000, 4000]
PROFILE = np.array([0.55, 0.7, 0.85, 1.0, 1.1, 1.2])  # relative absorption per octave band
WORDS = ("ball goal robot kick pass left right keeper striker defender field line penalty whistle "
         "corner throw half time referee team play game score fast slow turn walk stand fall up down "
         "attack defend wait stop now here there look go yes no one two three four five six").split()
VOICES = ["en", "en-us", "en-gb-x-rp", "de", "fr", "es", "en+f3", "en-us+f2", "de+m3", "fr+f4"]
# name, floor corners (m), height (m), nominal T60 (s)
ROOMS = [
    ("lshape-lab-0.5", [[0, 0], [12, 0], [12, 5], [7, 5], [7, 8], [0, 8]], 3.0, 0.5),
    ("lshape-lab-1.2", [[0, 0], [12, 0], [12, 5], [7, 5], [7, 8], [0, 8]], 3.0, 1.2),
    ("pent-hall-1.2", [[0, 0], [30, 0], [30, 14], [24, 20], [0, 20]], 8.0, 1.2),
    ("pent-hall-2.0", [[0, 0], [30, 0], [30, 14], [24, 20], [0, 20]], 8.0, 2.0),
]
# (SNR dB, two senders overlapping?)
CONDITIONS = [(20, False), (0, False), (10, True)]


def inside(corners, p):
    """Ray casting: is the floor point p inside the polygon?"""
    x, y, hit = p[0], p[1], False
    for (x1, y1), (x2, y2) in zip(corners, corners[1:] + corners[:1]):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            hit = not hit
    return hit


def point(corners, z_lo, z_hi, near=None, dist=(1.0, 8.0)):
    xs = [c[0] for c in corners]; ys = [c[1] for c in corners]
    for _ in range(10000):
        if near is None:
            p = [rng.uniform(min(xs) + 0.5, max(xs) - 0.5), rng.uniform(min(ys) + 0.5, max(ys) - 0.5)]
        else:
            d, a = rng.uniform(*dist), rng.uniform(0, 2 * np.pi)
            p = [near[0] + d * np.cos(a), near[1] + d * np.sin(a)]
        # at least 0.5 m from every wall: inside the polygon shrunk by testing a small ring
        if all(inside(corners, [p[0] + 0.5 * np.cos(t), p[1] + 0.5 * np.sin(t)]) for t in np.linspace(0, 2 * np.pi, 8, endpoint=False)):
            return [p[0], p[1], rng.uniform(z_lo, z_hi)]
    raise RuntimeError("no position found")


def rirs(corners, height, scale, sources, mic):
    coeffs = np.clip(PROFILE * scale, 0.01, 0.99)
    mat = pra.Material(energy_absorption={"coeffs": list(coeffs), "center_freqs": FREQS}, scattering=0.15)
    room = pra.Room.from_corners(np.array(corners).T, fs=RATE, materials=mat, max_order=3,
                                 ray_tracing=True, air_absorption=True)
    room.extrude(height, materials=mat)
    room.set_ray_tracing(receiver_radius=0.5, n_rays=6000, energy_thres=1e-6)
    for s in sources:
        room.add_source(s)
    room.add_microphone(mic)
    room.compute_rir()
    return [np.array(room.rir[0][k]) for k in range(len(sources))]


def t30(h):
    return float(pra.experimental.measure_rt60(h, fs=RATE, decay_db=30))


def build_room(name, corners, height, t60):
    mic = point(corners, 0.3, 0.6)
    senders = [point(corners, 0.3, 0.6, near=mic) for _ in range(3)]
    talkers = [point(corners, 1.5, 1.8) for _ in range(4)]
    # Sabine's guess, then a few multiplicative steps on the measured T30 of two sender paths.
    area_floor = abs(np.sum([c[0] * d[1] - d[0] * c[1] for c, d in zip(corners, corners[1:] + corners[:1])])) / 2
    perim = sum(np.hypot(c[0] - d[0], c[1] - d[1]) for c, d in zip(corners, corners[1:] + corners[:1]))
    vol, surf = area_floor * height, 2 * area_floor + perim * height
    scale = min(0.9, 0.161 * vol / (surf * t60))
    for _ in range(8):
        hs = rirs(corners, height, scale, senders[:2], mic)
        meas = float(np.mean([t30(h) for h in hs]))
        if abs(meas / t60 - 1) < 0.12:
            break
        scale = float(np.clip(scale * (meas / t60) ** 1.0, 0.005, 0.95))
    hs = rirs(corners, height, scale, senders + talkers, mic)
    meas = float(np.mean([t30(h) for h in hs[:3]]))
    dist = [round(float(np.hypot(p[0] - mic[0], p[1] - mic[1])), 2) for p in senders]
    return dict(name=name, t60=t60, t30=meas, scale=scale, senders=hs[:3], talkers=hs[3:], dist=dist)


def utterance(k):
    text = " ".join(rng.choice(WORDS) for _ in range(rng.randint(3, 14)))
    raw = f"{OUT}/u{k}.wav"
    run(["espeak-ng", "-v", rng.choice(VOICES), "-s", str(rng.randint(120, 210)), "-p", str(rng.randint(15, 85)), "-w", raw, text])
    r, x = wavfile.read(raw)
    os.remove(raw)
    x = x.astype(np.float64) / 32768
    return signal.resample_poly(x, RATE, r) if r != RATE else x


def babble(length, room):
    out = np.zeros(length)
    k = 0
    for h in rng.sample(room["talkers"], rng.randint(2, 4)):
        dry = np.zeros(length)
        gain = 10 ** (rng.uniform(-6, 6) / 20)
        pos = int(rng.uniform(0, 3) * RATE)
        while pos < length:
            u = utterance(k); k += 1
            n = min(len(u), length - pos)
            dry[pos:pos + n] += gain * u[:n]
            pos += n + int(rng.uniform(0.3, 4.0) * RATE)
        out += signal.fftconvolve(dry, h)[:length]
    return out


def clocked(x, speed):
    """The sender's clock `speed` times fast: the same samples played faster."""
    n = int(len(x) / speed)
    return np.interp(np.arange(n) * speed, np.arange(len(x)), x)


def encode(sender, kind, value):
    path = f"{OUT}/msg.wav"
    run([HUDDLE, "audio", "encode", "--team", "checked", "--sender", str(sender),
         "--long" if kind == "long" else "--data", str(value), path])
    return read(path)


def draw_message():
    return ("long", rng.randrange(121)) if rng.random() < 0.5 else ("short", rng.randrange(10))


def condition(room, snr, two):
    length = int((4 + SPACING * PER) * RATE)
    speeds = [1 + rng.choice([-1, 1]) * rng.uniform(0.001, 0.005) for _ in range(3)]
    per_sender = [np.zeros(length) for _ in range(3)]
    msgs = []  # (start s, duration s, kind, sender, value)
    for m in range(PER):
        sender = rng.randrange(3)
        starts = [(sender, 2 + SPACING * m + rng.uniform(0, 1.5))]
        if two:
            other = rng.choice([s for s in range(3) if s != sender])
            starts.append((other, starts[0][1] + rng.uniform(-1.5, 1.5)))
        for s, t0 in starts:
            kind, value = draw_message()
            x = clocked(encode(s, kind, value), speeds[s]) * 10 ** (rng.uniform(-3, 3) / 20)
            a = int(t0 * RATE)
            per_sender[s][a:a + len(x)] += x[: max(0, length - a)]
            msgs.append((t0, len(x) / RATE, kind, s, value))
    wets = [signal.fftconvolve(per_sender[s], room["senders"][s])[:length] for s in range(3)]
    wet = sum(wets)
    bab = babble(length, room)
    on = np.zeros(length, bool)
    on_s = [np.zeros(length, bool) for _ in range(3)]
    for (t0, d, _k, s, _v) in msgs:
        on[int(t0 * RATE):int((t0 + d) * RATE)] = True
        on_s[s][int(t0 * RATE):int((t0 + d) * RATE)] = True
    p_msg = float(np.mean(signal.sosfilt(BAND, wet)[on] ** 2))
    p_bab = float(np.mean(signal.sosfilt(BAND, bab) ** 2))
    g2 = p_msg / (p_bab * 10 ** (snr / 10))
    # Each sender's own SNR (its distance and the room's path make it differ from the row's).
    sender_snr = [round(10 * np.log10(max(1e-30, float(np.mean(signal.sosfilt(BAND, wets[s])[on_s[s]] ** 2)))
                                      / (g2 * p_bab)), 1) if on_s[s].any() else None for s in range(3)]
    room["sender_snr"] = sender_snr
    # Each message's local SNR: its own wet power over the babble's during its frames (one
    # sender's rows; with two senders the other robot is interference, not counted here).
    bab_band = signal.sosfilt(BAND, bab) ** 2 * g2
    wet_band = [signal.sosfilt(BAND, w) ** 2 for w in wets]
    for i, (t0, d, k, s, v) in enumerate(msgs):
        a, z = int(t0 * RATE), min(length, int((t0 + d) * RATE))
        loc = 10 * np.log10(max(1e-30, float(np.mean(wet_band[s][a:z]))) / max(1e-30, float(np.mean(bab_band[a:z]))))
        msgs[i] = (t0, d, k, s, v, round(float(loc), 1))
    mix = wet + np.sqrt(g2) * bab
    mix *= 0.5 / max(1e-9, float(np.max(np.abs(mix))))
    path = f"{OUT}/mix-{SEED}-{room['name']}-{snr}-{int(two)}.wav"
    wavfile.write(path, RATE, mix.astype(np.float32))
    rows = [score(room, snr, two, msgs, decode(h, path), b) for b, h in enumerate(HUDDLES)]
    if os.environ.get("KEEPALL") == "1":
        with open(path + ".json", "w") as f:
            json.dump(dict(room=dict(name=room["name"], t60=room["t60"], t30=room["t30"], dist=room["dist"],
                                     sender_snr=room["sender_snr"]), snr=snr, two=two, msgs=msgs), f)
    elif os.environ.get("KEEP") != f"{room['name']},{snr},{int(two)}":
        os.remove(path)
    return rows


def rescore():
    """RESCORE=1: decode the mixes a KEEPALL=1 run left in OUTDIR with HUDDLES, same audio."""
    rows = []
    for name in sorted(os.listdir(OUT)):
        if name.startswith(f"mix-{SEED}-") and name.endswith(".wav.json"):
            meta = json.load(open(os.path.join(OUT, name)))
            path = os.path.join(OUT, name[:-5])
            for b, h in enumerate(HUDDLES):
                row = score(meta["room"], meta["snr"], meta["two"], [tuple(m) for m in meta["msgs"]], decode(h, path), b)
                print(json.dumps(row), flush=True)
                rows.append(row)
    return rows


def decode(huddle, path):
    res = subprocess.run([huddle, "audio", "decode", "--team", "checked", "--json", path], capture_output=True, text=True)
    if res.returncode != 0:
        print(f"decode failed on {path}: {res.stderr[-500:]}", file=sys.stderr)
    return [json.loads(l) for l in res.stdout.splitlines() if l.startswith("{")]


def score(room, snr, two, msgs, dec, b):
    right = {"short": 0, "long": 0}; sent = {"short": 0, "long": 0}
    right0 = {"short": 0, "long": 0}; sent0 = {"short": 0, "long": 0}  # senders at their own SNR >= 0 dB
    rightl = {"short": 0, "long": 0}; sentl = {"short": 0, "long": 0}  # local SNR >= 0 dB
    loc_lost = []
    ssnr = room.get("sender_snr") or [None] * 3
    for m in msgs:
        (t0, d, kind, s, v), loc = m[:5], (m[5] if len(m) > 5 else None)
        sent[kind] += 1
        ok = any(t0 - 0.6 <= x["t"] <= t0 + d + 0.6 and (x["kind"], x["sender"], x["data"]) == (kind, s, v) for x in dec)
        right[kind] += ok
        if ssnr[s] is not None and ssnr[s] >= 0:
            sent0[kind] += 1
            right0[kind] += ok
        if loc is not None and not two:
            if loc >= 0:
                sentl[kind] += 1
                rightl[kind] += ok
            if not ok:
                loc_lost.append((kind, loc))
    msgs = [m[:5] for m in msgs]
    wrong = false = 0
    for x in dec:
        near = [mm for mm in msgs if mm[0] - 0.6 <= x["t"] <= mm[0] + mm[1] + 0.6]
        if not near:
            false += 1
            print(f"FALSE bin {b} {room['name']} snr {snr} two {two}: {x}", file=sys.stderr)
        elif not any((x["kind"], x["sender"], x["data"]) == (k, s, v) for (_, _, k, s, v) in near):
            wrong += 1
            print(f"WRONG bin {b} {room['name']} snr {snr} two {two}: decoded {x} near "
                  f"{[(round(t0, 2), k, s, v) for (t0, _, k, s, v) in near]}", file=sys.stderr)
    return dict(seed=SEED, bin=b, room=room["name"], t60=room["t60"], t30=round(room["t30"], 2), snr=snr, two=two,
                short=f"{right['short']}/{sent['short']}", long=f"{right['long']}/{sent['long']}",
                short_own0=f"{right0['short']}/{sent0['short']}", long_own0=f"{right0['long']}/{sent0['long']}",
                short_loc0=f"{rightl['short']}/{sentl['short']}", long_loc0=f"{rightl['long']}/{sentl['long']}",
                loc_lost=loc_lost,
                sender_snr=ssnr, dist=room.get("dist"), wrong=wrong, false=false, right=right["short"] + right["long"], sent=len(msgs))


def main():
    rows = rescore() if os.environ.get("RESCORE") == "1" else generate()
    for b in range(len(HUDDLES)):
        mine = [r for r in rows if r["bin"] == b]
        print(json.dumps(dict(seed=SEED, bin=b, huddle=HUDDLES[b], total=f"{sum(r['right'] for r in mine)}/{sum(r['sent'] for r in mine)}",
                              wrong=sum(r["wrong"] for r in mine), false=sum(r["false"] for r in mine))))


def generate():
    rows = []
    for (name, corners, height, t60) in ROOMS[int(os.environ.get("FIRST","0")):int(os.environ.get("LAST","4"))]:
        room = build_room(name, corners, height, t60)
        print(f"room {name}: nominal T60 {t60} s, measured T30 {room['t30']:.2f} s (absorption scale {room['scale']:.3f})", file=sys.stderr)
        for (snr, two) in CONDITIONS:
            for row in condition(room, snr, two):
                print(json.dumps(row), flush=True)
                rows.append(row)
    return rows


main()
