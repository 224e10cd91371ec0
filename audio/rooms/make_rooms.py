#!/usr/bin/env python3
"""Builds a room set for `huddle audio rooms`: image-source rooms and speech babble.

What it writes (all WAVs 16 kHz, 32-bit float, one channel) under OUT:

* `rir/<room>-s<k>.wav`: impulse responses from robot positions (0.3-0.6 m high) to the
  listening robot's microphone, and `rir/<room>-t<k>.wav` from talkers (1.5-1.8 m high).
  Rooms are pyroomacoustics shoeboxes (image-source method): halls of about 30x20x8 m and
  labs of about 12x8x3 m, robots 1-8 m from the microphone. A room's wall absorption is
  searched until the T60 measured on its own impulse responses (pyroomacoustics'
  Schroeder-curve T30 fit) is within 10% of the nominal one: Sabine's formula alone gives
  shoeboxes up to twice the reverberation asked for. T60 0 is the free field (direct
  path only).
* `babble/<k>.wav`: espeak-ng talkers (several languages, voices, speeds and pitches)
  reading random sentences, with the pauses between sentences kept as digital silence
  (no floor is added anywhere).
* `manifest.txt`: one line per file, `room NAME T60_NOMINAL T60_MEASURED`,
  `sender NAME PATH`, `talker NAME PATH`, `babble PATH`.

Everything is drawn from `--seed`, so a set is reproducible. The Rust side
(audio::evaluation::scene) mixes messages, talkers and clock errors itself.

Needs: python3 with numpy, scipy, pyroomacoustics (PyPI) and espeak-ng (apt);
scripts/install-rooms.sh installs them.
"""

import argparse
import os
import random
import subprocess
import sys
import tempfile
import wave

import numpy as np
import pyroomacoustics as pra
from scipy.io import wavfile
from scipy.signal import resample_poly

RATE = 16_000

WORDS = (
    "ball goal pass left right keeper striker defend kick the a to now here there "
    "quick slow wait go back forward field line corner penalty robot team half time "
    "look turn stop behind ahead open space mine yours again careful wide near far "
    "and but then when if not yes no one two three four five six seven eight nine "
    "ten lab test motor battery camera sensor walk stand fall get up listen shout"
).split()

VOICES = ["en", "en-us", "de", "fr", "es", "it", "nl", "pt", "sv", "pl"]
VARIANTS = ["m1", "m2", "m3", "m4", "f1", "f2", "f3", "f4", "croak", "klatt"]


def write_f32(path, x):
    wavfile.write(path, RATE, np.asarray(x, dtype=np.float32))


def talker_track(rng, seconds, tmp):
    """One talker: sentences with pauses (digital silence) until `seconds` are filled."""
    voice = f"{rng.choice(VOICES)}+{rng.choice(VARIANTS)}"
    speed = rng.randint(120, 200)
    pitch = rng.randint(20, 80)
    out = []
    total = 0
    while total < seconds * RATE:
        words = " ".join(rng.choice(WORDS) for _ in range(rng.randint(3, 14)))
        path = os.path.join(tmp, "say.wav")
        subprocess.run(
            ["espeak-ng", "-v", voice, "-s", str(speed), "-p", str(pitch), "-w", path, words],
            check=True,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        with wave.open(path) as w:
            rate = w.getframerate()
            x = np.frombuffer(w.readframes(w.getnframes()), dtype=np.int16).astype(np.float32)
        x = resample_poly(x / 32768.0, RATE, rate).astype(np.float32)
        pause = np.zeros(int(rng.uniform(0.2, 3.0) * RATE), dtype=np.float32)
        out += [x, pause]
        total += len(x) + len(pause)
    return np.concatenate(out)[: int(seconds * RATE)]


def place(rng, dim, height):
    return [rng.uniform(0.5, dim[0] - 0.5), rng.uniform(0.5, dim[1] - 0.5), height]


def robot_near(rng, dim, mic):
    """A robot 1-8 m from the microphone, inside the room."""
    for _ in range(1000):
        r = rng.uniform(1.0, 8.0)
        a = rng.uniform(0.0, 2.0 * np.pi)
        x, y = mic[0] + r * np.cos(a), mic[1] + r * np.sin(a)
        if 0.3 < x < dim[0] - 0.3 and 0.3 < y < dim[1] - 0.3:
            return [x, y, rng.uniform(0.3, 0.6)]
    raise RuntimeError("no robot position fits")


def build_room(dim, absorption, max_order, sources, mic):
    room = pra.ShoeBox(
        dim, fs=RATE, materials=pra.Material(absorption), max_order=max_order, air_absorption=True
    )
    for s in sources:
        room.add_source(s)
    room.add_microphone(mic)
    room.compute_rir()
    return room


def rirs_for_t60(dim, t60, sources, mic):
    """Impulse responses whose measured T60 is within 10% of `t60` (0: free field)."""
    if t60 == 0.0:
        room = build_room(dim, 0.99, 0, sources, mic)
        return [np.asarray(h, dtype=np.float64) for h in room.rir[0]], 0.0
    # Absorption e: Sabine's value first, then bisect on the measured T60 of a probe.
    # Bisection on log(e): small rooms need up to twice Sabine's absorption.
    e, max_order = pra.inverse_sabine(t60, dim)
    lo, hi = np.log(e * 0.3), np.log(0.99)
    probe = sources[:1]
    for _ in range(12):
        room = build_room(dim, e, max_order, probe, mic)
        measured = float(room.measure_rt60()[0][0])
        if abs(measured / t60 - 1.0) < 0.06:
            break
        if measured > t60:
            lo = np.log(e)
        else:
            hi = np.log(e)
        e = float(np.exp(0.5 * (lo + hi)))
    room = build_room(dim, e, max_order, sources, mic)
    measured = float(np.median(room.measure_rt60()))
    return [np.asarray(h, dtype=np.float64) for h in room.rir[0]], measured


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--t60", default="0,0.5,1.2,2.0", help="nominal T60s, s (0: free field)")
    ap.add_argument("--kinds", default="lab,hall", help="room kinds: lab, hall")
    ap.add_argument("--senders", type=int, default=4, help="robot positions per room")
    ap.add_argument("--talkers", type=int, default=8, help="talker positions per room")
    ap.add_argument("--babble-tracks", type=int, default=8)
    ap.add_argument("--babble-seconds", type=float, default=90.0)
    args = ap.parse_args()

    rng = random.Random(args.seed)
    os.makedirs(os.path.join(args.out, "rir"), exist_ok=True)
    os.makedirs(os.path.join(args.out, "babble"), exist_ok=True)
    lines = [f"# huddle room set, seed {args.seed}"]
    for t60 in [float(t) for t in args.t60.split(",")]:
        for kind in args.kinds.split(","):
            if kind == "lab":
                dim = [rng.uniform(10, 14), rng.uniform(7, 9), rng.uniform(2.8, 3.5)]
            else:
                dim = [rng.uniform(25, 35), rng.uniform(17, 23), rng.uniform(7, 9)]
            mic = place(rng, dim, rng.uniform(0.3, 0.6))
            robots = [robot_near(rng, dim, mic) for _ in range(args.senders)]
            talkers = [place(rng, dim, rng.uniform(1.5, 1.8)) for _ in range(args.talkers)]
            rirs, measured = rirs_for_t60(dim, t60, robots + talkers, mic)
            name = f"{kind}-{t60:g}"
            lines.append(f"room {name} {t60:g} {measured:.3f}")
            for k, h in enumerate(rirs):
                role, index = ("sender", k) if k < len(robots) else ("talker", k - len(robots))
                path = f"rir/{name}-{role[0]}{index}.wav"
                write_f32(os.path.join(args.out, path), h)
                lines.append(f"{role} {name} {path}")
            print(f"{name}: T60 {t60:g} s asked, {measured:.2f} s measured", file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.babble_tracks):
            x = talker_track(rng, args.babble_seconds, tmp)
            path = f"babble/{k}.wav"
            write_f32(os.path.join(args.out, path), x)
            lines.append(f"babble {path}")
    with open(os.path.join(args.out, "manifest.txt"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
