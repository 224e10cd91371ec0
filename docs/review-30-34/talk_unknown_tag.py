"""Review probe for finding 5 of docs/review-30-34.md: a newer build's talk message with a
value tag this build does not know. A crafted robot 9 (format 4, from the wire docs, as the
attack suite's newer build) posts `plan` messages 1 (an Int) and 2 (value tag 6, unknown),
then 3 (an Int), and keeps re-sending 2 with its talk head, as a sender answering NACKs
would. Loopback only. Usage, from the repository root:
    python3 docs/review-30-34/talk_unknown_tag.py /path/to/huddle
"""
import os, random, sys, time
sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "attack"))
import hwire as w
from harness import Daemon, multicast_sender, scratch_group, team_net

rng = random.Random(5)
group, port = scratch_group(rng)
d = Daemon(sys.argv[1], 1, team_net(group, port, 7))
sock = multicast_sender()
names = ["items_skipped", "talk_delivered", "talk_given_up", "nacks_sent", "drops.malformed", "frames_out"]
try:
    c = d.client()
    before = c.stats(names)
    inc = rng.getrandbits(62) | 1
    unknown = w.string("plan") + w.varint(2) + bytes([6, 1, 2])  # talk fields, value tag 6
    for seq in range(1, 41):
        items = [w.item4(w.ITEM_TALK_HEAD, w.head_fields("plan", 1, 3 if seq > 1 else 2))]
        if seq == 1:
            items.append(w.item4(w.ITEM_TALK, w.talk_fields("plan", 1, 5)))
        items.append(w.item4(w.ITEM_TALK, unknown))
        if seq > 1:
            items.append(w.item4(w.ITEM_TALK, w.talk_fields("plan", 3, 7)))
        sock.sendto(w.frame(7, 9, inc, seq, items), (group, port))
        time.sleep(0.1)
        if seq % 10 == 0:
            now = c.stats(names)
            print("t=%.1fs" % (seq * 0.1), {k: now[k] - before[k] for k in names}, flush=True)
    time.sleep(1.5)
    now = c.stats(names)
    print("end", {k: now[k] - before[k] for k in names})
finally:
    d.stop()
