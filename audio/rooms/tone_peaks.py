#!/usr/bin/env python3
"""Where each tone of the plan peaks after a room's impulse response (for diagnosis).

For every sender impulse response of a room set, every tone k and clock errors across
+-0.5%, a lone 1 s tone (10 ms fades) is sent through the room and analysed as the
decoder's off-grid check does: Hann windows of 2048 samples, half overlapping, zero-padded
to 4096, summed over the steady part of the slot (from a quarter in), the peak located by
a parabola through the log power of the loudest bin and its neighbours. Printed per tone:
how often its peak lies more than 0.5 Hz from the frequency sent, and how often its power
on the bin the sent frequency rounds to is under 0.7 of the loudest bin near it (the
decoder's "no common scale" share), and its level at the microphone (geometric mean over
the responses and clock errors, to the median tone's). No babble: what is left is the
room's doing.

usage: tone_peaks.py ROOMSET_DIR [ROOM ...]
"""
import sys
import numpy as np
from scipy.io import wavfile
from scipy.signal import fftconvolve

RATE = 16000
WIN = 2048
FFT = 4096
BIN = RATE / FFT


def tone_hz(k):
    return 500.0 + k * 3500.0 / 71.0


def read_rirs(root, room):
    rirs = []
    for line in open(f"{root}/manifest.txt"):
        p = line.split()
        if len(p) == 3 and p[0] == "sender" and p[1] == room:
            rate, h = wavfile.read(f"{root}/{p[2]}")
            assert rate == RATE
            h = h.astype(np.float64)
            if h.dtype.kind == "i":
                h /= 32768.0
            rirs.append(h)
    return rirs


def analyse(y, f):
    hann = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(WIN) / WIN)
    a, b = int(0.25 * RATE), int(1.0 * RATE)
    power = np.zeros(FFT // 2 + 1)
    for s in range(a, b - WIN + 1, WIN // 2):
        power += np.abs(np.fft.rfft(y[s:s + WIN] * hann, FFT)) ** 2
    lo = int(round(f * 0.994 / BIN)) - 1
    hi = int(round(f * 1.006 / BIN)) + 1
    p = lo + int(np.argmax(power[lo:hi + 1]))
    l, c, r = np.log(power[p - 1:p + 2] + 1e-30)
    den = l - 2 * c + r
    delta = 0.0 if den >= 0 else float(np.clip(0.5 * (l - r) / den, -0.5, 0.5))
    peak = (p + delta) * BIN
    share = power[int(round(f / BIN))] / power[p]
    return peak - f, share, power[p]


def main():
    root = sys.argv[1]
    rooms = sys.argv[2:] or [l.split()[1] for l in open(f"{root}/manifest.txt") if l.startswith("room ")]
    errors = np.linspace(-0.005, 0.005, 11)
    n = int(1.2 * RATE)
    t = np.arange(n) / RATE
    fade = int(0.01 * RATE)
    env = np.ones(n)
    env[int(1.0 * RATE):] = 0.0
    env[:fade] = 0.5 - 0.5 * np.cos(np.pi * (np.arange(fade) + 0.5) / fade)
    env[int(1.0 * RATE) - fade:int(1.0 * RATE)] = env[:fade][::-1]
    for room in rooms:
        rirs = read_rirs(root, room)
        off = np.zeros(72)
        low = np.zeros(72)
        mean_off = np.zeros(72)
        level = np.zeros(72)
        cases = 0
        for h in rirs:
            for e in errors:
                cases += 1
                for k in range(72):
                    f = tone_hz(k) * (1 + e)
                    y = fftconvolve(np.sin(2 * np.pi * f * t) * env, h)[:n]
                    d, share, p = analyse(y, f)
                    level[k] += np.log(p)
                    off[k] += abs(d) > 0.5
                    low[k] += share < 0.7
                    mean_off[k] += abs(d)
        print(f"{room}: {len(rirs)} sender responses x {len(errors)} clock errors")
        level = 10 * (level / cases - np.median(level / cases)) / np.log(10)
        print("  tone   Hz    |off|>0.5Hz  share<0.7  mean|off| Hz  level dB (geometric mean, to the median tone)")
        for k in range(72):
            print(f"  k{k:<3} {tone_hz(k):6.0f}  {off[k] / cases:9.2f}  {low[k] / cases:9.2f}  {mean_off[k] / cases:8.2f}  {level[k]:6.1f}")


if __name__ == "__main__":
    main()
