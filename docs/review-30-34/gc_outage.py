"""Review probe for finding 4 of docs/review-30-34.md: a daemon under `--budget spl` hears a
scripted GameController (Playing, second half, 300 s left) that says the team has 16
messages left (the margin for 5 robots is 14), while its program writes a value every
20 ms. Then the GC goes silent for 8 s (a WLAN outage of its broadcasts; a real GC would
still count every team message), then speaks again. Counts this daemon's frames in each
phase. Loopback only. Usage, from the repository root:
    python3 docs/review-30-34/gc_outage.py /path/to/huddle [SILENT_SECONDS, default 8]
"""
import os, random, socket, struct, sys, time
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "attack"))
from harness import Daemon, free_port, scratch_group, team_net

SILENT = int(sys.argv[2]) if len(sys.argv) > 2 else 8
rng = random.Random(5)
group, port = scratch_group(rng)
gc_port = free_port(socket.SOCK_DGRAM)
status = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
status.bind(("127.0.0.1", 0))
d = Daemon(sys.argv[1], 1, team_net(group, port, 12),
           extra=["--budget", "spl", "--gc-listen", "127.0.0.1:%d" % gc_port,
                  "--gc-status-port", str(status.getsockname()[1])])
gc = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
n = [0]
def rgme(budget):
    n[0] = (n[0] + 1) % 256
    b = bytearray(118); b[0:4] = b"RGme"; b[4] = 18; b[5] = n[0]; b[6] = 5; b[10] = 3; b[12] = 0; b[13] = 12
    struct.pack_into("<hh", b, 14, 300, 0)
    for i, t in enumerate((12, 34)):
        o = 18 + 50 * i; b[o] = t; b[o + 3] = 1; struct.pack_into("<H", b, o + 8, budget)
    return bytes(b)
try:
    c = d.client()
    def phase(name, secs, gc_on, budget):
        start = c.stat("frames_out"); t0 = time.time(); k = 0; nextgc = 0
        while time.time() - t0 < secs:
            if gc_on and time.time() >= nextgc:
                gc.sendto(rgme(budget), ("127.0.0.1", gc_port)); nextgc = time.time() + 0.5
            c.ask("SETV *.var.x %d" % k); k += 1
            time.sleep(0.02)
        time.sleep(0.3)
        print("%-34s frames_out +%d  (gc.budget key: %s)" % (name, c.stat("frames_out") - start,
              c.ask("GETV local.var.gc.budget")[:60]), flush=True)
    phase("GC heard, 16 left (margin 14)", 4, True, 16)
    phase("GC silent %d s" % SILENT, SILENT, False, 16)
    phase("GC heard again, 16 left", 3, True, 16)
finally:
    d.stop()
