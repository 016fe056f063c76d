#!/usr/bin/env python3
"""Load test of a real penumbra daemon on loopback, bounded in clients and time.

Starts `penumbra serve` on a free 127.0.0.1 port, warms it up, then runs CLIENTS threads for
SECONDS: a mix of synchronous renders (methods and sizes drawn from a fixed list), async jobs
(submit, follow the event stream, download), uploads of small distinct scenes rendered by id,
and stats reads. Every 0.5 s it samples the daemon's resident memory (/proc) and queue depth
(/v1/stats). Writes OUT/load.json (throughput, p50/p95/p99 latency per method, answers by
status, memory min/max after warm-up, queue depth) and OUT/load.png (latency and memory over
time). Only 200/201/202 and the documented 429 are expected; anything else is an error.

  deploy/load.py --binary target/release/penumbra --clients 16 --seconds 300 --out load-out
"""

import argparse
import hashlib
import json
import os
import random
import socket
import struct
import subprocess
import threading
import time
import urllib.error
import urllib.request

METHODS = ["hard", "pcss", "brabec", "jfa-l", "jfa-e", "chun-oh"]
SCENES = ["torus", "crowd", "columns", "occluder"]
SIZES = [(128, 96), (256, 192), (384, 288)]
EXPECTED = {200, 201, 202, 429}


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def request(base, method, path, body=None, headers=None, timeout=300):
    """One HTTP exchange: (status, body bytes); connection failures are status 0."""
    data = json.dumps(body).encode() if isinstance(body, (dict, list)) else body
    req = urllib.request.Request(base + path, data=data, method=method, headers=headers or {})
    if isinstance(body, (dict, list)):
        req.add_header("content-type", "application/json")
    try:
        with urllib.request.urlopen(req, timeout=timeout) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as error:
        return error.code, error.read()
    except (urllib.error.URLError, OSError):
        return 0, b""


def height_field_glb(n, seed):
    """A GLB height field of n×n vertices, distinct for every seed (like penumbra's own)."""
    rng = random.Random(seed)
    positions = b"".join(
        struct.pack("<3f", 4 * x / (n - 1) - 2, 0.3 + 0.3 * rng.random(), 4 * z / (n - 1) - 2) for z in range(n) for x in range(n)
    )
    indices = b"".join(
        struct.pack("<6I", i, i + n, i + 1, i + 1, i + n, i + n + 1) for z in range(n - 1) for x in range(n - 1) for i in [z * n + x]
    )
    binary = positions + indices
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
            {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n * n, "type": "VEC3", "min": [-2, 0.3, -2], "max": [2, 0.6, 2]},
            {"bufferView": 1, "componentType": 5125, "count": 6 * (n - 1) ** 2, "type": "SCALAR"},
        ],
    }
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(js) + 8 + len(binary)
    return b"glTF" + struct.pack("<II", 2, total) + struct.pack("<I", len(js)) + b"JSON" + js + struct.pack("<I", len(binary)) + b"BIN\0" + binary


class Recorder:
    def __init__(self):
        self.lock = threading.Lock()
        self.requests = []  # (t, kind, method, status, ms)

    def add(self, t, kind, method, status, ms):
        with self.lock:
            self.requests.append((t, kind, method, status, ms))


def client(base, index, deadline, started, recorder):
    rng = random.Random(index)
    counter = 0
    while time.time() < deadline:
        counter += 1
        roll = rng.random()
        method = rng.choice(METHODS)
        width, height = rng.choice(SIZES)
        job = {"scene": {"builtin": rng.choice(SCENES)}, "method": {"name": method}, "output": {"width": width, "height": height}}
        t0 = time.time()
        if roll < 0.5:
            status, _ = request(base, "POST", "/v1/render", job)
            recorder.add(t0 - started, "render", method, status, (time.time() - t0) * 1e3)
        elif roll < 0.75:
            status, body = request(base, "POST", "/v1/jobs", job)
            if status == 202:
                job_id = json.loads(body)["id"]
                request(base, "GET", f"/v1/jobs/{job_id}/events")
                status, _ = request(base, "GET", f"/v1/jobs/{job_id}/image")
            recorder.add(t0 - started, "async", method, status, (time.time() - t0) * 1e3)
        elif roll < 0.9:
            glb = height_field_glb(12, index * 100_000 + counter)
            scene_id = hashlib.sha256(glb).hexdigest()
            status, _ = request(base, "PUT", f"/v1/scenes/{scene_id}", glb, {"content-type": "model/gltf-binary"})
            recorder.add(t0 - started, "upload", "", status, (time.time() - t0) * 1e3)
            if status in (200, 201):
                t1 = time.time()
                job["scene"] = {"id": scene_id}
                status, _ = request(base, "POST", "/v1/render", job)
                recorder.add(t1 - started, "render", method, status, (time.time() - t1) * 1e3)
        else:
            status, _ = request(base, "GET", "/v1/stats")
            recorder.add(t0 - started, "stats", "", status, (time.time() - t0) * 1e3)
        if status == 429:
            time.sleep(1.0)


def rss_bytes(pid):
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def percentile(values, q):
    values = sorted(values)
    return values[min(len(values) - 1, round((len(values) - 1) * q))] if values else 0.0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--binary", default="target/release/penumbra")
    parser.add_argument("--clients", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=120)
    parser.add_argument("--warm-up-seconds", type=float, default=10, help="excluded from the memory figures")
    parser.add_argument(
        "--warm-up-renders",
        type=int,
        default=150,
        help="the warm-up also lasts until this many renders have finished: a machine shared with other work renders fewer "
        "a second, and its caches and pools fill later",
    )
    parser.add_argument("--out", default="load-out")
    parser.add_argument(
        "--cache-mib",
        type=float,
        default=8,
        help="the daemon's upload cache budget: small, so the cache is full (and memory flat) early in the run",
    )
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)

    port = free_port()
    base = f"http://127.0.0.1:{port}"
    # The shipped model: measuring this device's in the background would share the cores and
    # the memory whose floor the run watches.
    env = dict(os.environ, PENUMBRA_LOG="warn", PENUMBRA_LISTEN=f"127.0.0.1:{port}", PENUMBRA_MODEL="default")
    # Every upload is a distinct scene: with the default 1 GiB budget the upload cache would
    # still be filling at the end of the run, and memory with it.
    cache_bytes = str(int(args.cache_mib * 2**20))
    command = [args.binary, "serve", "--job-store", "memory", "--queue", "64", "--cache-bytes", cache_bytes]
    daemon = subprocess.Popen(command, env=env, stderr=subprocess.DEVNULL)
    try:
        for _ in range(600):
            if request(base, "GET", "/readyz", timeout=2)[0] == 200:
                break
            time.sleep(0.2)
        else:
            raise SystemExit("the daemon did not become ready")
        started = time.time()
        deadline = started + args.seconds
        recorder = Recorder()
        samples = []  # (t, rss, queued, in_flight)

        def sample():
            while time.time() < deadline:
                status, body = request(base, "GET", "/v1/stats", timeout=10)
                stats = json.loads(body) if status == 200 else {}
                samples.append((time.time() - started, rss_bytes(daemon.pid), stats.get("jobs_queued", 0), stats.get("jobs_in_flight", 0)))
                time.sleep(0.5)

        threads = [threading.Thread(target=client, args=(base, k, deadline, started, recorder)) for k in range(args.clients)]
        threads.append(threading.Thread(target=sample))
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        elapsed = time.time() - started
    finally:
        daemon.terminate()
        daemon.wait(timeout=120)

    requests = recorder.requests
    by_status = {}
    for _, _, _, status, _ in requests:
        by_status[str(status)] = by_status.get(str(status), 0) + 1
    renders = [r for r in requests if r[1] in ("render", "async") and r[3] == 200]
    per_method = {}
    for method in METHODS:
        ms = [r[4] for r in renders if r[2] == method]
        if ms:
            per_method[method] = {"jobs": len(ms), "p50_ms": percentile(ms, 0.5), "p95_ms": percentile(ms, 0.95), "p99_ms": percentile(ms, 0.99)}
    # Warm: past the seconds asked for and the renders asked for, whichever comes later.
    finished = sorted(r[0] + r[4] / 1e3 for r in renders)
    warm_from = args.warm_up_seconds
    if 0 < args.warm_up_renders <= len(finished):
        warm_from = max(warm_from, finished[args.warm_up_renders - 1])
    steady = [s[1] for s in samples if s[0] >= warm_from] or [s[1] for s in samples]
    # Growth of the floor (between renders' transient peaks): the lowest memory in the last
    # quarter of the steady run against the lowest in its first quarter. A leak raises it.
    quarter = max(1, len(steady) // 4)
    floor_growth = min(steady[-quarter:], default=0) - min(steady[:quarter], default=0)
    report = {
        "clients": args.clients,
        "seconds": elapsed,
        "requests": len(requests),
        "renders_per_second": len(renders) / elapsed,
        "by_status": by_status,
        "unexpected": sum(n for s, n in by_status.items() if int(s) not in EXPECTED),
        "latency_by_method": per_method,
        "warm_from_seconds": warm_from,
        "rss_after_warm_up_bytes": {"min": min(steady, default=0), "max": max(steady, default=0), "floor_growth": floor_growth},
        "upload_cache_bytes": int(cache_bytes),
        "queue_depth_max": max((s[2] for s in samples), default=0),
        "daemon_exit_code": daemon.returncode,
    }
    with open(os.path.join(args.out, "load.json"), "w") as f:
        json.dump(report, f, indent=2)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (top, bottom) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    for method in METHODS:
        points = [(r[0], r[4]) for r in renders if r[2] == method]
        if points:
            top.scatter([p[0] for p in points], [p[1] for p in points], s=6, label=method)
    top.set_yscale("log")
    top.set_ylabel("latency (ms)")
    top.legend(ncol=6, fontsize=8)
    top.set_title(f"penumbra under {args.clients} clients: {report['renders_per_second']:.2f} renders/s, {report['unexpected']} unexpected answers")
    bottom.plot([s[0] for s in samples], [s[1] / 2**20 for s in samples], color="tab:red", label="resident memory (MiB)")
    bottom.set_ylabel("RSS (MiB)")
    depth = bottom.twinx()
    depth.step([s[0] for s in samples], [s[2] for s in samples], color="tab:blue", where="post", label="queued")
    depth.set_ylabel("jobs queued")
    bottom.set_xlabel("seconds")
    figure.tight_layout()
    figure.savefig(os.path.join(args.out, "load.png"), dpi=100)
    print(json.dumps(report, indent=2))
    return 0 if report["unexpected"] == 0 and daemon.returncode == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
