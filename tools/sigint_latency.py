"""Sends SIGINT to `tarn build INPUT --out OUT` at given times and reports how long it
took to stop, and whether OUT was left byte for byte and no staging folder was left.

    python tools/sigint_latency.py TARN INPUT OUT SECONDS...
"""
import subprocess, time, sys, os, hashlib, signal
tarn, inp, out = sys.argv[1], sys.argv[2], sys.argv[3]
def snap(d):
    return {f: hashlib.sha256(open(os.path.join(d, f), 'rb').read()).hexdigest() for f in sorted(os.listdir(d))} if os.path.isdir(d) else {}
before = snap(out)
for t in [float(x) for x in sys.argv[4:]]:
    p = subprocess.Popen([tarn, "build", inp, "--out", out], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    time.sleep(t)
    t0 = time.time()
    p.send_signal(signal.SIGINT)
    o, e = p.communicate()
    dt = time.time() - t0
    same = snap(out) == before
    parent = os.path.dirname(os.path.abspath(out))
    stale = [f for f in os.listdir(parent) if '.tarn-stage-' in f]
    print(f"SIGINT at {t:5.1f} s: exit {p.returncode} after {dt:.2f} s; outputs unchanged {same}; staging left {stale}; {e.decode().strip()[-90:]}")
