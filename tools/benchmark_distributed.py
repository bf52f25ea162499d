#!/usr/bin/env python3
"""Distributed benchmark (docs/distributed.md): laps per second of the Spielberg study's
candidates on 1 and 2 threads (rayon, in this process) and on a Dask LocalCluster of 1 and
2 worker processes, for the bench with our EDU and with the pythonfmu supplier EDU; and on
a cluster of `dask scheduler`/`dask worker` processes (1, 2 and 4 workers) that do not see
the study's folder, so that its files travel with the tasks, with the bytes they carry.

Each row evaluates the same generation-sized batches of candidates of the study's first
step (what `Study.optimize` hands its executor), after one warm-up batch that loads the
study on every worker. Dask's overhead per candidate is the 1-worker time minus the
1-thread time, per candidate, as a share of a lap.

Usage: tools/benchmark_distributed.sh [--candidates 16] [--batches 2] [--quick] [--json]
                                      [--cluster-only]
"""
import argparse
import datetime
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))
import twinbench  # noqa: E402
from benchmark import machine  # noqa: E402
from dask_cluster import Cluster, project  # noqa: E402


def supplier_study(tmp):
    """The Spielberg study with the supplier's EDU swapped in (systems/rls_v_supplier.toml)."""
    text = open(os.path.join(ROOT, "studies", "spielberg.toml")).read()
    text = text.replace('system = "../systems/rls_v.toml"', f'system = "{os.path.join(ROOT, "systems", "rls_v_supplier.toml")}"')
    text = text.replace('measurement = "../data/spielberg_lap.csv"', f'measurement = "{os.path.join(ROOT, "data", "spielberg_lap.csv")}"')
    path = os.path.join(tmp, "spielberg_supplier.toml")
    with open(path, "w") as f:
        f.write(text)
    return path


def batches(study, n, count, seed=1):
    step = study.steps[0]
    rng = random.Random(seed)
    return [[[lo + rng.random() * (hi - lo) for lo, hi in step.bounds] for _ in range(n)] for _ in range(count)]


def timed(evaluate, work):
    evaluate(work[0])  # warm-up: loads the study (on every worker), not counted
    t0 = time.perf_counter()
    for batch in work[1:]:
        evaluate(batch)
    return time.perf_counter() - t0


def measure(path, n, count, workers_list, label):
    from dask.distributed import Client, LocalCluster

    study = twinbench.Study(path)
    work = batches(study, n, count + 1)
    laps = n * count
    rows = {}
    for threads in (1, 2):
        wall = timed(lambda b: study.evaluate(0, b, threads=threads), work)
        rows[f"{label}: {threads} thread{'s' if threads > 1 else ''} (rayon)"] = {"wall": wall, "laps": laps}
    for workers in workers_list:
        with tempfile.TemporaryDirectory() as scratch:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, local_directory=scratch)
            client = Client(cluster)
            try:
                ex = client.get_executor()
                wall = timed(lambda b: study.evaluate(0, b, executor=ex), work)
            finally:
                client.close()
                cluster.close()
        rows[f"{label}: Dask LocalCluster, {workers} worker{'s' if workers > 1 else ''}"] = {"wall": wall, "laps": laps}
    for r in rows.values():
        r["laps_per_s"] = r["laps"] / r["wall"]
        r["s_per_lap"] = r["wall"] / r["laps"]
    one = rows[f"{label}: 1 thread (rayon)"]
    two = rows[f"{label}: 2 threads (rayon)"]
    summary = {}
    if 1 in workers_list and label == "our EDU":
        # (With the pythonfmu EDU the in-process rows share this interpreter's GIL with the
        # FMU's Python code, so their difference to a worker process is no overhead.)
        d1 = rows[f"{label}: Dask LocalCluster, 1 worker"]
        summary["dask_overhead_per_candidate_s"] = d1["s_per_lap"] - one["s_per_lap"]
        summary["dask_overhead_share_of_lap"] = summary["dask_overhead_per_candidate_s"] / one["s_per_lap"]
    if 2 in workers_list:
        d2 = rows[f"{label}: Dask LocalCluster, 2 workers"]
        summary["dask2_over_rayon2"] = d2["laps_per_s"] / two["laps_per_s"]
    return rows, summary


def measure_cluster(n, count, workers_list):
    """Separate scheduler and worker processes that cannot see the study's folder: laps
    per second, the overhead per candidate over this process's one thread, and the bytes
    the study's files and tasks carry."""
    import pickle

    from twinbench import _shipping, _worker

    rows, summary = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        path = project(tmp / "project")
        study = twinbench.Study(path)
        work = batches(study, n, count + 1)
        laps = n * count
        one = timed(lambda b: study.evaluate(0, b, threads=1), work)
        rows["cluster bench: 1 thread in this process (rayon)"] = {"wall": one, "laps": laps}
        for workers in workers_list:
            c = Cluster(tmp / f"cluster{workers}", tmp / "project")
            try:
                for k in range(workers):
                    c.start_worker(f"w{k + 1}")
                c.wait_for(workers)
                ex = _shipping.shipping(c.client.get_executor(), os.fspath(path), study._loaded())
                try:
                    wall = timed(lambda b: study.evaluate(0, b, executor=ex), work)
                    shipped = ex.shipment.bytes_per_study
                    values = list(study.assignment().values())
                    task = len(pickle.dumps((_worker.cost, ex.shipment.arg, study._loaded().digest, 0, values)))
                finally:
                    ex.close()
            finally:
                c.close()
            rows[f"cluster without the study's folder: {workers} worker process{'es' if workers > 1 else ''}"] = {
                "wall": wall, "laps": laps}
            summary[f"{workers} workers: bytes of the study's files, sent once to each worker"] = shipped
            summary["bytes per task (a candidate: the files' names and digests, the values)"] = task
    for r in rows.values():
        r["laps_per_s"] = r["laps"] / r["wall"]
        r["s_per_lap"] = r["wall"] / r["laps"]
    base = rows["cluster bench: 1 thread in this process (rayon)"]["s_per_lap"]
    w1 = rows["cluster without the study's folder: 1 worker process"]["s_per_lap"]
    summary["overhead per candidate over one thread [s]"] = w1 - base
    summary["overhead share of a lap"] = (w1 - base) / base
    summary["bytes per generation of %d candidates" % n] = n * summary["bytes per task (a candidate: the files' names and digests, the values)"]
    return rows, summary


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candidates", type=int, default=16, help="candidates per batch (a generation)")
    ap.add_argument("--batches", type=int, default=2, help="timed batches per row")
    ap.add_argument("--quick", action="store_true", help="skip the supplier EDU")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--cluster-only", action="store_true",
                    help="only the cluster of separate processes without the study's folder")
    a = ap.parse_args()
    result = {"date": datetime.date.today().isoformat(), "machine": machine(), "rows": {}, "summary": {}}
    if not a.cluster_only:
        rows, s = measure(os.path.join(ROOT, "studies", "spielberg.toml"), a.candidates, a.batches, (1, 2), "our EDU")
        result["rows"].update(rows)
        result["summary"]["our EDU"] = s
    rows, s = measure_cluster(a.candidates, a.batches, (1, 2, 4))
    result["rows"].update(rows)
    result["summary"]["cluster"] = s
    if not a.quick and not a.cluster_only:
        with tempfile.TemporaryDirectory() as tmp:
            # The supplier EDU costs tens of µs per step: fewer laps give the same precision.
            rows, s = measure(supplier_study(tmp), max(2, a.candidates // 4), 1, (1, 2), "supplier EDU (pythonfmu)")
        result["rows"].update(rows)
        result["summary"]["supplier EDU (pythonfmu)"] = s
    if a.json:
        print(json.dumps(result, indent=1))
        return 0
    m = result["machine"]
    print(f"Date {result['date']}; machine: {m['cpu']}, nproc {m['nproc']}, {m['os']}, Python {m['python']}.")
    print(f"Candidates of the Spielberg study's first step, {a.candidates} per batch, after a warm-up batch.\n")
    print("| where | laps | wall [s] | laps per second | s per lap |")
    print("|---|---:|---:|---:|---:|")
    for name, r in result["rows"].items():
        print(f"| {name} | {r['laps']} | {r['wall']:.2f} | {r['laps_per_s']:.2f} | {r['s_per_lap']:.3f} |")
    print()
    for label, s in result["summary"].items():
        if label == "cluster":
            for k, v in s.items():
                print(f"- cluster: {k}: {v:,.4g}")
            continue
        parts = []
        if "dask2_over_rayon2" in s:
            parts.append(f"Dask 2 workers at {100 * s['dask2_over_rayon2']:.0f} % of 2 rayon threads")
        if "dask_overhead_per_candidate_s" in s:
            parts.append(
                f"Dask overhead {1e3 * s['dask_overhead_per_candidate_s']:.1f} ms per candidate "
                f"({100 * s['dask_overhead_share_of_lap']:.1f} % of a lap)"
            )
        print(f"- {label}: " + "; ".join(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
