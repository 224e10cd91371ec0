"""A late joiner written with the official Zenoh Python API (eclipse-zenoh).

Usage: mirror_sub.py PORT VENUE TEAM. Subscribes to the team's values and presence,
then gets the bridge's replica, merging every sample by (incarnation, version) so that a
reply older than a sample already held never rolls a value back. Prints READY, then
answers DUMP (one JSON line) and QUIT on stdin.
"""
import json
import sys
import threading

import zenoh

port, venue, team = sys.argv[1], sys.argv[2], sys.argv[3]
prefix = f"huddle/@v1/{venue}/{team}"
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)

lock = threading.Lock()
state = {}
samples = []
got = []
alive = []


def order(sample):
    fields = dict(f.split("=", 1) for f in sample.attachment.to_string().split())
    return (int(fields["incarnation"], 16), int(fields["version"]))


def merge(sample, into):
    key = str(sample.key_expr)
    payload = sample.payload.to_string()
    attachment = sample.attachment.to_string() if sample.attachment is not None else ""
    with lock:
        into.append([key, payload, attachment])
        o = order(sample)
        if key not in state or state[key][0] < list(o):
            state[key] = [list(o), payload]


def on_alive(sample):
    with lock:
        alive.append([str(sample.kind), str(sample.key_expr)])


sub = session.declare_subscriber(f"{prefix}/**", lambda s: merge(s, samples))
lsub = session.liveliness().declare_subscriber(f"{prefix}/*/@alive/*", on_alive, history=True)
for reply in session.get(f"{prefix}/**"):
    if reply.ok is not None:
        merge(reply.ok, got)

print("READY", flush=True)
for line in sys.stdin:
    cmd = line.strip()
    if cmd == "DUMP":
        with lock:
            print(json.dumps({
                "state": {k: v[1] for k, v in state.items()},
                "samples": samples,
                "got": got,
                "alive": alive,
            }), flush=True)
    elif cmd == "QUIT":
        break
session.close()
