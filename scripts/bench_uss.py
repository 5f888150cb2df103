#!/usr/bin/env python3
"""Loopback load test of the F3548 USS-USS interface (issue 25; BENCHMARKS.md).

    source scripts/env.sh
    python scripts/bench_uss.py [--rate 25 --duration 900 --peers 10 --seconds 60]

1. Intents: the approvals of an in-process run on the Singapore network at ``--rate`` requests
   per 30 s (25 = 3,000 flights/h) for ``--duration`` simulated seconds (FIFO, fast), put into an
   :class:`uam_sim.f3548.uss_server.IntentStore` and served by the real :class:`UssServer` (Flask on a
   bounded pool of ``--workers`` threads) on 127.0.0.1; the store's clock is at t = 0, so every intent
   is served whole (all its volumes: the largest answers). With ``--auth verify`` (the default, as
   deployed) every request carries an RS256 token of a development key pair, verified by the server.
2. Nominal load (open loop): details requests arrive as a Poisson process of rate
   3,000 flights/h x ``--peers`` (each flight's intent fetched by that many peer USSs) for
   ``--seconds`` s, each sent by a pool of client threads at its arrival time; latency = answer
   received - arrival (queueing in the client included).
3. Stress (closed loop): ``--clients`` threads each send the next request as soon as the last was
   answered, for ``--stress-seconds`` s: the throughput ceiling on this machine.

Every answer must be 200 (a random intent id of the store); the script checks 1 in 50 against the
F3548 schema. Prints a table and ``uptime`` (load distorts latency).
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import random
import subprocess
import threading
import time

import numpy as np
import requests


def build_store(args):
    from uam_planner.f3548 import IntentContext, VolumeSpec
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario
    from uam_sim.f3548.uss_server import IntentStore

    net = load_network_spec(args.network)
    got = []
    t = time.perf_counter()
    run_scenario(net, "fifo", args.rate, args.seed, args.duration, make_config({"audit": False}),
                 observer=lambda t_s, k, s, rj, res: got.extend(res.approved))
    store = IntentStore(IntentContext(net.origin_lat_lon_alt, VolumeSpec.for_separation(100.0)))
    ids = [store.put_flight(f) for f in got]
    print(f"intents: {len(ids)} approvals of a {args.duration:g} s FIFO run at {args.rate:g} per 30 s "
          f"({time.perf_counter() - t:.1f} s to plan and convert)")
    return store, ids


def percentiles(lat_s):
    a = np.asarray(lat_s) * 1000.0
    return (len(a), *np.percentile(a, [50, 95, 99]), a.max()) if len(a) else (0, 0, 0, 0, 0)


def one(session_of, url, ids, rng_lock, rng, check):
    with rng_lock:
        oid = ids[rng.randrange(len(ids))]
        do_check = rng.random() < 0.02
    r = session_of().get(f"{url}/uss/v1/operational_intents/{oid}", timeout=30)
    if r.status_code != 200:
        raise RuntimeError(f"{oid}: HTTP {r.status_code}: {r.text[:200]}")
    if do_check:
        errs = check(r.json(), "GetOperationalIntentDetailsResponse")
        if errs:
            raise RuntimeError(f"{oid}: schema: {errs[:3]}")
    return len(r.content)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--network", default="config/networks/singapore.yaml")
    ap.add_argument("--rate", type=float, default=25.0, help="requests per 30 s of the run (25 = 3,000/h)")
    ap.add_argument("--duration", type=float, default=900.0, help="simulated seconds of the run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--peers", type=int, default=10, help="peer USSs fetching each flight's intent")
    ap.add_argument("--seconds", type=float, default=60.0, help="wall seconds of the nominal load")
    ap.add_argument("--stress-seconds", type=float, default=20.0)
    ap.add_argument("--clients", type=int, default=4, help="client threads of the stress load")
    ap.add_argument("--auth", choices=("verify", "off"), default="verify",
                    help="the server's auth (verify: a token of a development key on every request)")
    ap.add_argument("--workers", type=int, default=8, help="the server's worker threads")
    args = ap.parse_args(argv)

    import tempfile

    from uam_planner.f3548_schema import errors
    from uam_sim.f3548.auth import generate_dev_keys, mint_token
    from uam_sim.f3548.uss_server import SCOPE_INTENTS, UssServer

    store, ids = build_store(args)
    keys = tempfile.TemporaryDirectory(prefix="bench-uss-keys-")
    private, public = generate_dev_keys(keys.name)
    srv = UssServer(store, port=0, auth=args.auth, auth_key=str(public), workers=args.workers).start()
    headers = {"Authorization": f"Bearer {mint_token(private, 'localhost', [SCOPE_INTENTS])}"}
    local = threading.local()

    def session_of():
        if not hasattr(local, "s"):
            local.s = requests.Session()
            local.s.headers.update(headers)
        return local.s

    rng, rng_lock = random.Random(args.seed), threading.Lock()
    try:
        # nominal: Poisson arrivals, open loop
        lam = 3000.0 / 3600.0 * args.peers
        arrivals, t = [], 0.0
        arr_rng = random.Random(args.seed + 1)
        while True:
            t += arr_rng.expovariate(lam)
            if t > args.seconds:
                break
            arrivals.append(t)
        lat, sizes = [], []
        pool = cf.ThreadPoolExecutor(max_workers=8)
        start = time.perf_counter()
        futs = []
        for a in arrivals:
            delay = start + a - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            futs.append((a, pool.submit(one, session_of, srv.url, ids, rng_lock, rng, errors)))
            # latency measured at completion through a callback
            futs[-1][1].add_done_callback(lambda f, a=a: lat.append(time.perf_counter() - start - a))
        for _, f in futs:
            sizes.append(f.result())
        pool.shutdown()
        nominal = percentiles(lat)
        # stress: closed loop
        stop_at = time.perf_counter() + args.stress_seconds
        s_lat = []
        s_lock = threading.Lock()

        def client():
            while time.perf_counter() < stop_at:
                t0 = time.perf_counter()
                one(session_of, srv.url, ids, rng_lock, rng, errors)
                with s_lock:
                    s_lat.append(time.perf_counter() - t0)

        threads = [threading.Thread(target=client) for _ in range(args.clients)]
        t0 = time.perf_counter()
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        stress = percentiles(s_lat)
        wall = time.perf_counter() - t0
    finally:
        srv.stop()
        keys.cleanup()
    print(f"auth {args.auth}, {args.workers} workers")
    print(f"answers: mean {np.mean(sizes) / 1024:.0f} KiB, max {np.max(sizes) / 1024:.0f} KiB "
          f"(volumes of 5 s; 4 vertices each)")
    print("| load | requests | rate [req/s] | p50 [ms] | p95 [ms] | p99 [ms] | max [ms] |")
    print("|---|---|---|---|---|---|---|")
    print(f"| nominal: 3,000 flights/h x {args.peers} peers, Poisson, open loop | {nominal[0]} | "
          f"{nominal[0] / args.seconds:.1f} | " + " | ".join(f"{v:.1f}" for v in nominal[1:]) + " |")
    print(f"| stress: {args.clients} clients, closed loop | {stress[0]} | {stress[0] / wall:.1f} | "
          + " | ".join(f"{v:.1f}" for v in stress[1:]) + " |")
    print("uptime:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
