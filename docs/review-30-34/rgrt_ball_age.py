# One daemon (team layer on, GC listener on a test port); the program writes its pose and ONE
# ball sighting, then nothing more. A scripted GC sends RGme every 0.5 s; we read the RGrt
# status packets for 8 s and print ballAge, and local.var.team.ball's own age_s field.
# Loopback only: the daemon on 127.0.0.1 with a scratch group; the GC and status sockets on 127.0.0.1.
# Usage: python3 rgrt_ball_age.py /path/to/huddle
import socket, struct, subprocess, time, sys, random, tempfile
BIN=sys.argv[1]
def free_udp():
    s=socket.socket(socket.AF_INET,socket.SOCK_DGRAM); s.bind(("127.0.0.1",0)); p=s.getsockname()[1]; s.close(); return p
def free_tcp():
    s=socket.socket(); s.bind(("127.0.0.1",0)); p=s.getsockname()[1]; s.close(); return p
gc_port=free_udp(); relay=free_tcp(); gport=free_udp()
status=socket.socket(socket.AF_INET,socket.SOCK_DGRAM); status.bind(("127.0.0.1",0)); status.settimeout(0.1)
group=f"239.{random.randint(1,250)}.{random.randint(1,250)}.{random.randint(1,250)}:{gport}"
d=subprocess.Popen([BIN,"daemon","--id","1","--team","12","--group",group,"--iface","127.0.0.1","--relay",f"127.0.0.1:{relay}",
  "--config-dir",tempfile.mkdtemp(),"--gamecontroller","--gc-listen",f"127.0.0.1:{gc_port}","--gc-status-port",str(status.getsockname()[1])],
  stdout=subprocess.DEVNULL,stderr=subprocess.DEVNULL)
try:
    for _ in range(50):
        try: c=socket.create_connection(("127.0.0.1",relay)); break
        except OSError: time.sleep(0.1)
    f=c.makefile("rw")
    def ask(line):
        f.write(line+"\n"); f.flush(); return f.readline().strip()
    print(ask("SETV local.var.robot.pose [0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]"))
    print(ask("SETV local.var.robot.ball [1.5, 0.0, 0.01, 0.0, 0.01]"))
    # RGme v18, team 12 vs 34, Playing
    def rgme(n):
        b=bytearray(118); b[0:4]=b"RGme"; b[4]=18; b[5]=n; b[6]=5; b[10]=3; b[12]=1; b[13]=12
        struct.pack_into("<hh",b,14,500,0)
        for i,t in enumerate((12,34)):
            o=18+50*i; b[o]=t; b[o+3]=1; struct.pack_into("<H",b,o+8,1100)
        return bytes(b)
    gc=socket.socket(socket.AF_INET,socket.SOCK_DGRAM)
    t0=time.time(); n=0; nextgc=0
    while time.time()-t0<8:
        if time.time()>=nextgc:
            n=(n+1)%256; gc.sendto(rgme(n),("127.0.0.1",gc_port)); nextgc=time.time()+0.5
        try:
            data,_=status.recvfrom(64)
        except socket.timeout:
            continue
        hdr,ver,pn,tn,fallen,x,y,th,age,bx,by=struct.unpack("<4sBBBB6f",data)
        tb=ask("GETV local.var.team.ball")
        print(f"t={time.time()-t0:4.1f}s RGrt ballAge={age:6.2f} ball=({bx:.0f},{by:.0f}) mm | team.ball: {tb[:200]}")
finally:
    d.terminate(); d.wait()
