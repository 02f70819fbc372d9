#!/usr/bin/env python3
"""Hostile clients against facecapd's control API, measured (docs/control-api.md, "Limits").

Starts facecapd on the sim source (240 Hz) with the control API on a free loopback port,
runs one attack and prints what it cost: /status probes answered, missed deadlines (the
loop's counter) during the attack and in a quiet stretch of equal length before it, RSS
growth, log size. Exits 1 when a goal of issue 35 is missed.

  idle    N idle WebSocket clients (default 300) that never read, and 64 slowloris
          connections sending half a header; goals: every /status probe answered, no more
          missed deadlines than in the quiet stretch, RSS growth < 50 MB, log < 1 MB
  emfile  facecapd under `prlimit --nofile` a few descriptors above what it uses, and
          200 connections opened and held; goals: the log < 1 MB, deadlines as in quiet,
          /status answered once the connections are closed
  replay  a take recorded, then 40 clients reading /recordings/frames (count 60) in a
          loop while a second take is started and stopped; goals: record stop and start
          each answered within 0.5 s

Usage: scripts/control-attack.py {idle,emfile,replay} [--build DIR] [--seconds S] [--clients N]
"""
import argparse
import json
import os
import re
import resource
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def rss_mb(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return 0.0


class Daemon:
    def __init__(self, build, work, extra=(), prefix=()):
        self.log_path = os.path.join(work, "facecapd.log")
        env = dict(os.environ)
        if os.getuid() == 0:
            env["FACECAPD_ALLOW_ROOT"] = "1"
        args = [*prefix, os.path.join(build, "daemon", "facecapd"),
                "--set", "source.sim.rate_hz=240", "--set", "loop.rate_hz=240",
                "--set", f"outputs.shm.name=facecap-attack-{os.getpid()}",
                "--set", "control.http.enabled=true", "--set", "control.http.port=0",
                "--set", f"outputs.recording.directory={work}/takes", *extra]
        self.log = open(self.log_path, "w")
        self.proc = subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT, env=env)
        self.port = None
        for _ in range(600):
            text = open(self.log_path).read()
            m = re.search(r"control API on http://127\.0\.0\.1:(\d+)", text)
            if m and "ready: first frame solved" in text:
                self.port = int(m.group(1))
                break
            if self.proc.poll() is not None:
                sys.exit(f"facecapd stopped:\n{text}")
            time.sleep(0.1)
        else:
            sys.exit("facecapd did not start within 60 s")
        time.sleep(1)  # past the start-up ticks

    def request(self, method, path, body=None, timeout=10):
        data = json.dumps(body).encode() if body is not None else None
        req = urllib.request.Request(f"http://127.0.0.1:{self.port}{path}", data=data, method=method,
                                     headers={"Content-Type": "application/json"} if data else {})
        try:
            with urllib.request.urlopen(req, timeout=timeout) as r:
                return r.status, r.read()
        except urllib.error.HTTPError as e:
            return e.code, e.read()

    def missed(self):
        status, body = self.request("GET", "/metrics")
        m = re.search(rb"^facecap_missed_deadlines_total (\d+)$", body, re.M)
        return int(m.group(1)) if status == 200 and m else -1

    def log_bytes(self):
        return os.path.getsize(self.log_path)

    def stop(self):
        self.proc.terminate()
        try:
            self.proc.wait(15)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def probe_status(d, seconds, every=1.0):
    """GET /status on a new connection every `every` s for `seconds`: (answered, probes)."""
    answered = probes = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        probes += 1
        try:
            if d.request("GET", "/status", timeout=3)[0] == 200:
                answered += 1
        except OSError:
            pass
        time.sleep(every)
    return answered, probes


def quiet_missed(d, seconds):
    before = d.missed()
    time.sleep(seconds)
    return d.missed() - before


def open_websocket(port):
    """A WebSocket upgrade that is never read from again; the socket, or None if refused."""
    s = socket.create_connection(("127.0.0.1", port), timeout=5)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.sendall(b"GET /stream?rate=120&vertices=1 HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
              b"Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n")
    try:
        head = s.recv(64)
    except OSError:
        head = b""
    if head.startswith(b"HTTP/1.1 101"):
        return s
    s.close()
    return None


def slowloris(port):
    s = socket.create_connection(("127.0.0.1", port), timeout=5)
    s.sendall(b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\n")
    return s


def attack_idle(d, args):
    seconds = args.seconds
    rss_before, log_before = rss_mb(d.proc.pid), d.log_bytes()
    quiet = quiet_missed(d, seconds)
    before = d.missed()
    sockets, accepted = [], 0
    stop = threading.Event()

    def keep_slowloris():  # 64 at all times, reopened as the server closes them
        held = []
        while not stop.is_set():
            held = [s for s in held if s.fileno() >= 0]
            while len(held) < 64 and not stop.is_set():
                try:
                    held.append(slowloris(d.port))
                except OSError:
                    break
            for s in list(held):
                s.setblocking(False)
                try:
                    if s.recv(1) == b"":
                        s.close()
                        held.remove(s)
                except BlockingIOError:
                    pass
                except OSError:
                    s.close()
                    held.remove(s)
            time.sleep(0.2)
        for s in held:
            s.close()

    loris = threading.Thread(target=keep_slowloris)
    loris.start()
    for _ in range(args.clients):
        try:
            s = open_websocket(d.port)
        except OSError:
            s = None
        if s:
            accepted += 1
            sockets.append(s)
    answered, probes = probe_status(d, seconds)
    rss_peak = rss_mb(d.proc.pid)
    missed = d.missed() - before
    stop.set()
    loris.join()
    for s in sockets:
        s.close()
    log_growth = d.log_bytes() - log_before
    print(f"idle: {args.clients} WebSocket clients tried, {accepted} let in; 64 slowloris held for {seconds} s")
    print(f"  /status answered {answered}/{probes}; missed deadlines {missed} under attack, {quiet} in {seconds} s quiet")
    print(f"  RSS {rss_before:.0f} -> {rss_peak:.0f} MB (+{rss_peak - rss_before:.1f}); log +{log_growth} bytes")
    return answered == probes and missed <= quiet and rss_peak - rss_before < 50 and log_growth < 1 << 20


def attack_emfile(d, args):
    seconds = args.seconds
    log_before = d.log_bytes()
    quiet = quiet_missed(d, seconds)
    before = d.missed()
    held = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:  # keep 200 open: more than facecapd has descriptors for
        held = [s for s in held if s.fileno() >= 0]
        while len(held) < 200:
            try:
                held.append(slowloris(d.port))
            except OSError:
                break
        time.sleep(0.5)
    for s in held:  # the API cannot answer while facecapd has no descriptor left
        s.close()
    time.sleep(1.5)  # the back-off's longest wait
    missed = d.missed() - before
    answered, probes = probe_status(d, 3)
    text = open(d.log_path, errors="replace").read()
    warnings = text.count("accepting a connection failed")
    log_growth = d.log_bytes() - log_before
    print(f"emfile: 200 connections held for {seconds} s against RLIMIT_NOFILE {args.nofile}")
    print(f"  accept warnings logged {warnings}; log +{log_growth} bytes; missed deadlines {missed} "
          f"(quiet {quiet}); /status afterwards {answered}/{probes}")
    return warnings > 0 and log_growth < 1 << 20 and missed <= quiet and answered == probes


def attack_replay(d, args):
    status, _ = d.request("POST", "/record/start", {"take": "source"})
    assert status == 200, status
    time.sleep(5)
    status, body = d.request("POST", "/record/stop", {})
    assert status == 200, (status, body)
    name = os.path.basename(json.loads(body)["file"])
    rss_before = rss_mb(d.proc.pid)
    stop = threading.Event()
    counts = {"200": 0, "503": 0, "other": 0}
    lock = threading.Lock()

    def reader(k):
        while not stop.is_set():
            try:
                code, _ = d.request("GET", f"/recordings/frames?name={name}&first={k}&count=60", timeout=30)
            except OSError:
                code = 0
            with lock:
                counts[str(code) if str(code) in counts else "other"] += 1
            if code == 503:
                time.sleep(0.2)

    readers = [threading.Thread(target=reader, args=(k,)) for k in range(args.clients)]
    for t in readers:
        t.start()
    rss_peak = rss_before
    time.sleep(3)
    start_s, stop_s = [], []
    for n in range(3):
        t0 = time.monotonic()
        status_start, _ = d.request("POST", "/record/start", {"take": f"during{n}"}, timeout=60)
        start_s.append(time.monotonic() - t0)
        time.sleep(1)
        rss_peak = max(rss_peak, rss_mb(d.proc.pid))
        t0 = time.monotonic()
        status_stop, _ = d.request("POST", "/record/stop", {}, timeout=60)
        stop_s.append(time.monotonic() - t0)
        print(f"  take {n}: start {status_start} in {start_s[-1]:.3f} s, stop {status_stop} in {stop_s[-1]:.3f} s", flush=True)
        assert status_start == 200 and status_stop == 200, (status_start, status_stop)
        rss_peak = max(rss_peak, rss_mb(d.proc.pid))
        time.sleep(1)
    stop.set()
    for t in readers:
        t.join()
    print(f"replay: {args.clients} clients reading 60 frames at a time: {counts['200']} answered 200, "
          f"{counts['503']} 503, {counts['other']} other")
    print(f"  record start {', '.join(f'{s:.3f}' for s in start_s)} s; record stop "
          f"{', '.join(f'{s:.3f}' for s in stop_s)} s; RSS {rss_before:.0f} -> peak {rss_peak:.0f} MB")
    return max(start_s) < 0.5 and max(stop_s) < 0.5 and counts["other"] == 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("attack", choices=["idle", "emfile", "replay"])
    p.add_argument("--build", default=os.environ.get("FACECAP_BUILD_DIR", os.path.join(HERE, "build")))
    p.add_argument("--seconds", type=float, default=20)
    p.add_argument("--clients", type=int, default=None, help="WebSocket clients (idle, 300) or readers (replay, 40)")
    p.add_argument("--nofile", type=int, default=0, help="emfile: RLIMIT_NOFILE (default: 24 above what facecapd needs)")
    args = p.parse_args()
    if args.clients is None:
        args.clients = 300 if args.attack == "idle" else 40
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (max(soft, min(hard, 4096)), hard))  # ours, for the clients
    with tempfile.TemporaryDirectory() as work:
        prefix, extra = (), ()
        if args.attack == "emfile":
            probe = Daemon(args.build, work)  # how many descriptors facecapd holds when idle
            in_use = len(os.listdir(f"/proc/{probe.proc.pid}/fd"))
            probe.stop()
            args.nofile = args.nofile or in_use + 24
            prefix = ("prlimit", f"--nofile={args.nofile}")
            extra = ("--set", "control.http.max_connections=4096", "--set", "control.http.max_connections_per_address=4096")
        d = Daemon(args.build, work, extra, prefix)
        try:
            ok = {"idle": attack_idle, "emfile": attack_emfile, "replay": attack_replay}[args.attack](d, args)
        finally:
            d.stop()
    print("ok" if ok else "FAILED: a goal was missed")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
