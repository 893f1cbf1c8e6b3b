#!/usr/bin/env python3
"""multifit server vs. the Python peer (numpy + scikit-learn), measured in one run.

What it does, in order:

1. builds one realistic input of N correspondences (default 1000) from a real AdelaideRMF pair
   (default: bonhall, 1068 rows, 6 planes + outliers): a seeded subsample when N is at most the
   pair's size, otherwise every row plus seeded re-draws jittered by 0.5 px;
2. starts `target/release/multifit-server --addr 127.0.0.1:0 --workers W` for every W needed
   (or uses `--url` of a running server), reads the bound address from the line it prints on
   stdout, and waits for `/health/ready`;
3. checks that the peer's embeddings agree with the server's (`return_embeddings: true`);
4. latency: R fits of that input with `selection: silhouette`, `k_max: 8` and a fixed seed,
   each a `POST /v1/fit` (timed client-side, HTTP and JSON included, keep-alive connection) or an
   in-process Python peer fit (from the numpy array of raw pixels to labels, so the peer pays no
   parsing or HTTP; one BLAS / OpenMP thread unless `--py-threads` says otherwise); p50 / p90 of
   both and the ratio, twice: interleaved (one server fit, one peer fit, alternating) and in
   blocks (each side's R fits back to back). Where a core left idle for ~100 ms runs the next few
   milliseconds of work slower (benches/wake.rs), interleaving makes every server fit start cold
   while the peer's longer fits amortise it; blocks show each side warm;
5. throughput: C client threads send the same request back to back for T seconds against the
   server with `--workers 1`, then the one with `--workers 2`, alternating for `--rounds` rounds
   (the servers run side by side; an idle one costs nothing); requests per second summed over the
   rounds and the scaling ratio. By default the server gives each fit cores / workers threads
   (`--fit-threads`); `--server-args "--fit-threads 1"` measures one-thread fits instead;
6. prints a markdown table for the README (and `--json-out` writes every figure).

Everything is on the loopback interface, every loop is bounded, and the servers it started are
stopped (SIGTERM, then SIGKILL after 15 s) even when a step fails.

    python3 bench/compare.py                              # full run
    python3 bench/compare.py --requests 20 --seconds 5    # quick run
    python3 bench/compare.py --url http://127.0.0.1:8080  # a running server (no worker sweep)
    # 1000 tracks of 30 frames (the server reads 4 windows of 5 frames and refines):
    ./target/release/multifit-train gen-motion --out runs/data/motion30-bench --count 1 --seed 7 \
        --frames 30 --motions 4 --points 250
    python3 bench/compare.py --model kt3dmoseg --dataset runs/data/motion30-bench/motion-s7-00000.json

Needs numpy and scikit-learn (bench/requirements.txt) and a release build of the server.
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import platform
import selectors
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import urlparse

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import python_peer  # noqa: E402  (the peer lives next to this script)

REPO = Path(__file__).resolve().parent.parent
DEFAULT_DATASET = REPO.parent / "shared" / "datasets" / "adelaidermf" / "bonhall.json"
HTTP_TIMEOUT_S = 120


# -- input ----------------------------------------------------------------------------------------


def build_input(dataset: Path, n: int, seed: int) -> tuple[np.ndarray, list | None, int]:
    """N raw rows from a dataset file: (points [n, d] float64, image_size, true structures)."""
    data = json.loads(dataset.read_text())
    pts = np.asarray(data["points"], dtype=np.float64)
    rng = np.random.default_rng(seed)
    if n <= len(pts):
        idx = np.sort(rng.choice(len(pts), size=n, replace=False))
        pts = pts[idx]
    else:
        extra = pts[rng.integers(0, len(pts), size=n - len(pts))]
        extra = extra + rng.normal(0.0, 0.5, size=extra.shape)
        pts = np.vstack([pts, extra])
    return pts, data.get("image_size"), int(data.get("num_models", 0))


# -- the server -----------------------------------------------------------------------------------


class Server:
    """A multifit-server process on 127.0.0.1:<free port>; stop() ends it."""

    def __init__(self, binary: Path, models: Path, workers: int | None, start_timeout: float,
                 extra: list[str] = ()):
        cmd = [str(binary), "--addr", "127.0.0.1:0", "--models", str(models)]
        if workers is not None:
            cmd += ["--workers", str(workers)]
        cmd += list(extra)
        self.workers = workers
        self.log = tempfile.TemporaryFile()  # stderr (logs), shown if the start fails
        env = dict(os.environ, RUST_LOG="warn")
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.log, env=env)
        try:
            self.url = self._read_address(start_timeout)
            self._wait_ready(start_timeout)
        except Exception:
            self.stop()
            raise

    def _read_address(self, timeout: float) -> str:
        # The server prints one line, "multifit-server listening on http://ADDR", once bound
        # (tests/common/mod.rs reads it the same way).
        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        try:
            if not sel.select(timeout):
                raise RuntimeError(f"server announced no address within {timeout} s"
                                   f"{self._stderr_tail()}")
        finally:
            sel.close()
        line = self.proc.stdout.readline().decode(errors="replace").strip()
        if "http://" not in line:
            raise RuntimeError(f"unexpected first line {line!r}{self._stderr_tail()}")
        return "http://" + line.rsplit("http://", 1)[1]

    def _wait_ready(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(f"server exited with {self.proc.returncode}"
                                   f"{self._stderr_tail()}")
            try:
                status, _ = Client(self.url, timeout=2).get("/health/ready")
                if status == 200:
                    return
            except OSError:
                pass
            time.sleep(0.05)
        raise RuntimeError(f"server not ready within {timeout} s{self._stderr_tail()}")

    def _stderr_tail(self) -> str:
        self.log.seek(0)
        tail = self.log.read()[-2000:].decode(errors="replace")
        return f"; server log:\n{tail}" if tail else ""

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)  # drains in-flight requests, then exits
            try:
                self.proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout:
            self.proc.stdout.close()
        self.log.close()


class Client:
    """One keep-alive HTTP/1.1 connection (reconnects after an error)."""

    def __init__(self, url: str, timeout: float = HTTP_TIMEOUT_S):
        u = urlparse(url)
        self.host, self.port, self.timeout = u.hostname, u.port or 80, timeout
        self.conn: http.client.HTTPConnection | None = None

    def _request(self, method: str, path: str, body: bytes | None) -> tuple[int, bytes]:
        if self.conn is None:
            self.conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout)
        headers = {"content-type": "application/json"} if body is not None else {}
        try:
            self.conn.request(method, path, body=body, headers=headers)
            resp = self.conn.getresponse()
            return resp.status, resp.read()
        except (OSError, http.client.HTTPException):
            self.conn.close()
            self.conn = None
            raise

    def get(self, path: str) -> tuple[int, bytes]:
        return self._request("GET", path, None)

    def fit(self, body: bytes) -> tuple[int, bytes]:
        return self._request("POST", "/v1/fit", body)

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()


def fit_ok(client: Client, body: bytes) -> dict:
    status, data = client.fit(body)
    if status != 200:
        raise RuntimeError(f"POST /v1/fit answered {status}: {data[:300]!r}")
    return json.loads(data)


# -- measurements ---------------------------------------------------------------------------------


def pct(values, q: float) -> float:
    return float(np.percentile(np.asarray(values, dtype=np.float64), q))


def verify(url: str, peer: python_peer.Model, request: dict, points, image) -> dict:
    """One fit on both sides with embeddings returned; their agreement."""
    body = json.dumps(dict(request, return_embeddings=True)).encode()
    client = Client(url)
    try:
        server = fit_ok(client, body)
    finally:
        client.close()
    answer = peer.fit(points, image, k_max=request["k_max"], selection=request["selection"],
                      seed=request["seed"])
    return python_peer.compare_with_server(peer, answer, server)


def latency(url: str, peer: python_peer.Model, request: dict, points, image,
            requests: int, warmup: int, order: str) -> dict:
    """R server fits and R peer fits, after `warmup` of each. `order` "interleaved": one server
    fit, then one peer fit, and so on, so every fit starts right after ~100 ms of the other
    side's work (where an idle core slows down, each server fit then starts cold);
    "blocks": the R server fits back to back, then the R peer fits back to back (each side warm,
    as under steady traffic)."""
    body = json.dumps(request).encode()
    client = Client(url)
    server_ms, server_embed, server_cluster, server_k = [], [], [], []
    peer_ms, peer_embed, peer_cluster, peer_k = [], [], [], []

    def server_fit(record: bool) -> None:
        t0 = time.perf_counter()
        answer = fit_ok(client, body)
        if record:
            server_ms.append((time.perf_counter() - t0) * 1e3)
            server_embed.append(answer["timing_ms"]["embed"])
            server_cluster.append(answer["timing_ms"]["cluster"])
            server_k.append(answer["k"])

    def peer_fit(record: bool) -> None:
        t0 = time.perf_counter()
        mine = peer.fit(points, image, k_max=request["k_max"],
                        selection=request["selection"], seed=request["seed"])
        if record:
            peer_ms.append((time.perf_counter() - t0) * 1e3)
            peer_embed.append(mine["timing_ms"]["embed"])
            peer_cluster.append(mine["timing_ms"]["cluster"])
            peer_k.append(mine["k"])

    try:
        if order == "interleaved":
            for i in range(warmup + requests):
                server_fit(i >= warmup)
                peer_fit(i >= warmup)
        else:
            for i in range(warmup + requests):
                server_fit(i >= warmup)
            for i in range(warmup + requests):
                peer_fit(i >= warmup)
    finally:
        client.close()
    return {
        "order": order,
        "requests": requests,
        "server_p50_ms": pct(server_ms, 50),
        "server_p90_ms": pct(server_ms, 90),
        "server_embed_p50_ms": pct(server_embed, 50),
        "server_cluster_p50_ms": pct(server_cluster, 50),
        "server_k": sorted(set(server_k)),
        "peer_p50_ms": pct(peer_ms, 50),
        "peer_p90_ms": pct(peer_ms, 90),
        "peer_embed_p50_ms": pct(peer_embed, 50),
        "peer_cluster_p50_ms": pct(peer_cluster, 50),
        "peer_k": sorted(set(peer_k)),
        "ratio_p50": pct(peer_ms, 50) / pct(server_ms, 50),
    }


def throughput(url: str, request: dict, concurrency: int, seconds: float) -> dict:
    """C threads send fits back to back until the deadline; completed 200s per second."""
    body = json.dumps(request).encode()
    # Warm every connection (and the server's workers) before the clock starts.
    clients = [Client(url) for _ in range(concurrency)]
    warm = [threading.Thread(target=fit_ok, args=(c, body)) for c in clients]
    for t in warm:
        t.start()
    for t in warm:
        t.join(HTTP_TIMEOUT_S)
    lock = threading.Lock()
    counts = {"ok": 0, "rejected": 0, "errors": 0}
    latencies: list[float] = []
    ends: list[float] = []
    start = time.perf_counter()
    deadline = start + seconds

    def run(client: Client) -> None:
        while time.perf_counter() < deadline:
            t0 = time.perf_counter()
            try:
                status, _ = client.fit(body)
                key = "ok" if status == 200 else "rejected"  # 429 queue full, 503 timeout
            except (OSError, http.client.HTTPException):
                key = "errors"
            t1 = time.perf_counter()
            with lock:
                counts[key] += 1
                if key == "ok":
                    latencies.append((t1 - t0) * 1e3)
                ends.append(t1)

    threads = [threading.Thread(target=run, args=(c,), daemon=True) for c in clients]
    for t in threads:
        t.start()
    for t in threads:
        t.join(seconds + HTTP_TIMEOUT_S)
    for c in clients:
        c.close()
    elapsed = (max(ends) if ends else time.perf_counter()) - start
    return {
        "concurrency": concurrency,
        "seconds": elapsed,
        **counts,
        "rps": counts["ok"] / elapsed if elapsed > 0 else 0.0,
        "p50_ms": pct(latencies, 50) if latencies else None,
    }


# -- report ---------------------------------------------------------------------------------------


def machine() -> str:
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{os.cpu_count()} cores, {model or platform.processor() or platform.machine()}"


def table(res: dict) -> str:
    a = res["args"]
    agree = res["agreement"]
    head = (f"N = {a['n']}, `{a['model']}`, selection silhouette, k_max {a['k_max']}, "
            f"seed {a['seed']}")
    rows = []
    for lat in res["latency"]:
        how = ("one server fit, one peer fit, alternating" if lat["order"] == "interleaved"
               else "each side's fits back to back")
        rows += [
            (f"**{lat['order']}** ({how}; server `--workers {lat.get('server_workers', '?')}`)", ""),
            ("`POST /v1/fit` latency p50 / p90 (client-side, HTTP included)",
             f"{lat['server_p50_ms']:.1f} / {lat['server_p90_ms']:.1f} ms"),
            ("  of which embed / cluster p50 (server-reported)",
             f"{lat['server_embed_p50_ms']:.1f} / {lat['server_cluster_p50_ms']:.1f} ms"),
            ("Python peer (numpy + scikit-learn, in-process) p50 / p90",
             f"{lat['peer_p50_ms']:.1f} / {lat['peer_p90_ms']:.1f} ms"),
            ("  of which embed / cluster p50",
             f"{lat['peer_embed_p50_ms']:.1f} / {lat['peer_cluster_p50_ms']:.1f} ms"),
            ("latency ratio, Python p50 / multifit p50", f"{lat['ratio_p50']:.1f}x"),
        ]
    tp = res["throughput"]
    for w, t in tp.items():
        where = "the `--url` server" if w == "given" else f"`--workers {w}`"
        rows.append((f"throughput, {where}, {t['concurrency']} clients",
                     f"{t['rps']:.2f} req/s ({t['ok']} in {t['seconds']:.1f} s, "
                     f"{len(t['rounds_rps'])} rounds"
                     + (f", {t['rejected']} rejected" if t["rejected"] else "")
                     + (f", {t['errors']} errors" if t["errors"] else "") + ")"))
    if "1" in tp and "2" in tp and tp["1"]["rps"] > 0:
        rows.append(("throughput scaling, 2 workers / 1 worker",
                     f"{tp['2']['rps'] / tp['1']['rps']:.2f}x"))
    rows.append(("embeddings, max abs difference peer vs server",
                 f"{agree['embed_max_abs_diff']:.1e} (K: server {agree['k_server']}, "
                 f"peer {agree['k_peer']}; label ARI {agree['labels_ari']:.3f})"))
    lines = [f"| {head} | |", "|---|---|"] + [f"| {k} | {v} |" for k, v in rows]
    lines.append("")
    lines.append(f"{res['machine']}; {res['python']}; {res['command']}")
    return "\n".join(lines)


# -- main -----------------------------------------------------------------------------------------


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--requests", type=int, default=50, help="sequential fits per side (R)")
    ap.add_argument("--warmup", type=int, default=3, help="untimed fits per side first")
    ap.add_argument("--seconds", type=float, default=20.0, help="throughput run length (T)")
    ap.add_argument("--concurrency", type=int, default=4, help="client threads (C)")
    ap.add_argument("--rounds", type=int, default=2,
                    help="throughput rounds, alternating between the --workers servers")
    ap.add_argument("--model", default="adelaide-homography", help="model name under --models")
    ap.add_argument("--n", type=int, default=1000, help="points per fit")
    ap.add_argument("--dataset", type=Path, default=DEFAULT_DATASET,
                    help="dataset JSON the input is drawn from (rows must suit --model)")
    ap.add_argument("--seed", type=int, default=0, help="input sampling and k-means seed")
    ap.add_argument("--k-max", type=int, default=8)
    ap.add_argument("--workers", default="1,2",
                    help="comma-separated --workers values for the throughput runs")
    ap.add_argument("--latency-workers", type=int,
                    help="--workers of the server timed for latency (default: largest of "
                         "--workers)")
    ap.add_argument("--url", help="use this running server instead of starting ones")
    ap.add_argument("--binary", type=Path, default=REPO / "target/release/multifit-server")
    ap.add_argument("--models", type=Path, default=REPO / "models")
    ap.add_argument("--server-args", default="",
                    help="extra server flags, e.g. '--fit-threads 1' (default: the server's own "
                         "defaults, i.e. fit threads = cores / workers)")
    ap.add_argument("--py-threads", type=int, default=1,
                    help="BLAS / OpenMP threads of the peer (default 1: one fit on one core, "
                         "like one server worker; 0 = the libraries' defaults)")
    ap.add_argument("--start-timeout", type=float, default=60.0)
    ap.add_argument("--json-out", type=Path, help="also write every figure here as JSON")
    args = ap.parse_args()
    if min(args.requests, args.concurrency, args.n, args.rounds) < 1 or args.seconds <= 0:
        ap.error("--requests, --concurrency, --rounds, --n and --seconds must be positive")

    if args.py_threads:
        # On the 2-core development machine under other load, the peer with the libraries'
        # default 2 threads was about 15 times slower than with one (OpenMP threads spinning);
        # one thread is the peer's best setting there. Try --py-threads 0 on a quiet machine.
        from threadpoolctl import threadpool_limits
        threadpool_limits(args.py_threads)

    peer = python_peer.Model(args.models / args.model)
    points, image, truth_k = build_input(args.dataset, args.n, args.seed)
    request = {
        "kind": peer.kind,
        "model": args.model,
        "points": points.tolist(),
        "selection": "silhouette",
        "k_max": args.k_max,
        "seed": args.seed,
    }
    if image is not None:
        request["image_size"] = image
    print(f"input: {len(points)} rows from {args.dataset.name} "
          f"({truth_k} structures + outliers), image_size {image}", file=sys.stderr)

    import sklearn
    from threadpoolctl import threadpool_info
    pools = ", ".join(f"{p['internal_api']} {p['num_threads']} threads" for p in threadpool_info())
    res: dict = {
        "args": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
        "machine": machine(),
        "python": f"Python {platform.python_version()}, numpy {np.__version__}, "
                  f"scikit-learn {sklearn.__version__} ({pools})",
        "command": shlex.join(["python3", "bench/compare.py", *sys.argv[1:]]),
        "throughput": {},
    }

    def run_latency(url: str, label: str) -> None:
        print(f"[{label}] checking embeddings against the peer", file=sys.stderr)
        res["agreement"] = verify(url, peer, request, points, image)
        print(f"[{label}] {res['agreement']}", file=sys.stderr)
        res["latency"] = []
        for order in ("interleaved", "blocks"):
            print(f"[{label}] latency, {order}: {args.requests} fits per side", file=sys.stderr)
            lat = latency(url, peer, request, points, image, args.requests, args.warmup, order)
            lat["server_workers"] = label
            res["latency"].append(lat)
            print(f"[{label}] {lat}", file=sys.stderr)

    def run_throughput(urls: dict[str, str]) -> None:
        # Rounds alternate between the servers so that a change in background load hits every
        # configuration alike; the figures are summed over the rounds.
        for r in range(args.rounds):
            for label, url in urls.items():
                print(f"[{label}] throughput round {r + 1}/{args.rounds}: {args.concurrency} "
                      f"clients for {args.seconds} s", file=sys.stderr)
                t = throughput(url, request, args.concurrency, args.seconds)
                print(f"[{label}] {t}", file=sys.stderr)
                acc = res["throughput"].setdefault(label, {"concurrency": args.concurrency,
                                                          "seconds": 0.0, "ok": 0,
                                                          "rejected": 0, "errors": 0,
                                                          "rounds_rps": []})
                for key in ("seconds", "ok", "rejected", "errors"):
                    acc[key] += t[key]
                acc["rounds_rps"].append(t["rps"])
                acc["rps"] = acc["ok"] / acc["seconds"] if acc["seconds"] > 0 else 0.0

    if args.url:
        run_latency(args.url, "given")
        run_throughput({"given": args.url})
    else:
        if not args.binary.is_file():
            sys.exit(f"{args.binary} not found: run `cargo build --release` first")
        sweep = sorted({int(w) for w in args.workers.split(",") if w.strip()})
        lat_w = args.latency_workers or max(sweep)
        # Every configuration runs side by side (an idle server costs no CPU); all are stopped
        # on the way out, whatever happens.
        servers: dict[int, Server] = {}
        try:
            for w in sorted(set(sweep) | {lat_w}):
                servers[w] = Server(args.binary, args.models, w, args.start_timeout,
                                    shlex.split(args.server_args))
                print(f"[{w}] server with --workers {w} at {servers[w].url}", file=sys.stderr)
            run_latency(servers[lat_w].url, str(lat_w))
            run_throughput({str(w): servers[w].url for w in sweep})
        finally:
            for server in servers.values():
                server.stop()

    if args.json_out:
        args.json_out.write_text(json.dumps(res, indent=1) + "\n")
    print(table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
