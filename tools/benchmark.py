#!/usr/bin/env python3
"""Side-by-side benchmark: one lap of the 5-instance RLS/v bench at 1 ms, run by

  twinbench (FMUs, Gauss-Seidel), twinbench (native models), twinbench (FMUs, Jacobi),
  FMPy's FMU2Slave driven by tools/fmpy_cosim.py (Gauss-Seidel, the same algorithm),
  FMPy's simulate_ssp on the exported SSP (Jacobi), libcosim (libcosimpy) on the same SSP.

Reports wall time per lap (best of --repeat for the fast ones, one run for the Python
masters), ratio to twinbench, nanoseconds per macro step, and the cost per FMU call:
(wall - twinbench native wall) / FMU calls, i.e. what each master adds on top of the
models themselves. Prints a Markdown table (with date and machine), or JSON.

Usage: tools/benchmark.py [--repeat 5] [--quick] [--json]
  (run from the repository; builds nothing: `cargo build --release` and
   `target/release/twinbench pack` first, or use tools/benchmark.sh)
"""
import argparse
import datetime
import json
import os
import platform
import re
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TB = os.path.join(ROOT, "target", "release", "twinbench")
SYSTEM = os.path.join(ROOT, "systems", "rls_v.toml")
sys.path.insert(0, os.path.join(ROOT, "tools"))


def machine():
    cpu = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {"nproc": os.cpu_count(), "cpu": cpu, "os": platform.platform(), "python": platform.python_version()}


def system_variant(tmp, algorithm=None, stop=None, fmi=2):
    text = open(SYSTEM).read().replace('"../target/fmu/', '"' + os.path.join(ROOT, "target", "fmu") + "/")
    if fmi == 3:
        # The models' FMI 3.0 FMUs (`twinbench pack --fmi 2,3`): <model>-fmi3.fmu.
        for m in ("vehicle", "driver", "dyno", "edu"):
            text = text.replace(f'/{m}.fmu"', f'/{m}-fmi3.fmu"')
    if algorithm:
        text = text.replace('algorithm = "gauss-seidel"', f'algorithm = "{algorithm}"')
    if stop is not None:
        text = text.replace('stop = "vehicle.lap >= 1"', f"stop = {stop!r}")
    p = os.path.join(tmp, f"rls_v_{algorithm or 'gs'}_{stop or 'lap'}_fmi{fmi}.toml")
    with open(p, "w") as f:
        f.write(text)
    return p


def twinbench(system, repeat, native=False):
    walls, last = [], None
    for _ in range(repeat + 1):  # the first run warms caches and is not counted
        args = [TB, "run", system, "--json"] + (["--native"] if native else [])
        out = subprocess.run(args, check=True, capture_output=True, text=True).stdout
        last = json.loads(out)
        walls.append(last["wall_time"])
    walls = walls[1:]
    return {"wall": min(walls), "median": statistics.median(walls), "steps": last["steps"],
            "simulated": last["simulated_time"], "runs": len(walls)}


def fmpy_master(system):
    out = subprocess.run([sys.executable, os.path.join(ROOT, "tools", "fmpy_cosim.py"), system, "--json"],
                         check=True, capture_output=True, text=True).stdout
    j = json.loads(out)
    return {"wall": j["wall_time"], "median": j["wall_time"], "steps": j["steps"], "simulated": j["simulated_time"], "runs": 1}


def calls_per_step(system):
    """FMU calls per macro step of twinbench's (and fmpy_cosim's) master: per instance one
    doStep plus one set/get call per non-empty type batch."""
    import fmpy_cosim
    s = fmpy_cosim.System(system)
    n = 0
    for u in s.units:
        n += 1
        n += sum(1 for v in u.in_vr.values() if v)
        n += sum(1 for v in u.out_vr.values() if v)
    s.cleanup()
    return n


def simulate_ssp(ssp, stop, step):
    import ssp_check
    r = ssp_check.run_fmpy(ssp, stop, step)
    return {"wall": r["wall_time"], "median": r["wall_time"], "steps": r["steps"], "simulated": stop, "runs": 1}


def libcosim(ssp, stop, step, repeat):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import log_output_level, CosimLogLevel
    log_output_level(CosimLogLevel.ERROR)
    walls = []
    for _ in range(repeat):
        ex = CosimExecution.from_ssp_file(ssp)
        t0 = time.perf_counter()
        ok = ex.simulate_until(int(round(stop * 1e9)))
        walls.append(time.perf_counter() - t0)
        if not ok:
            raise RuntimeError("libcosim failed")
        del ex
    return {"wall": min(walls), "median": statistics.median(walls), "steps": int(round(stop / step)),
            "simulated": stop, "runs": len(walls)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="skip the two Python masters")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        gs = system_variant(tmp)
        jac = system_variant(tmp, "jacobi")
        rows["twinbench, FMUs (Gauss-Seidel)"] = twinbench(gs, a.repeat)
        rows["twinbench, native models (Gauss-Seidel)"] = twinbench(gs, a.repeat, native=True)
        rows["twinbench, FMUs (Jacobi)"] = twinbench(jac, a.repeat)
        lap = rows["twinbench, FMUs (Jacobi)"]["simulated"]
        step = 1e-3
        ssp_stop = round(lap * 1000) / 1000
        ssp = os.path.join(tmp, "bench.ssp")
        subprocess.run([TB, "export-ssp", system_variant(tmp, "jacobi", ssp_stop), "-o", ssp],
                       check=True, capture_output=True)
        if not a.quick:
            rows["FMPy FMU2Slave master, tools/fmpy_cosim.py (Gauss-Seidel)"] = fmpy_master(gs)
            rows["FMPy simulate_ssp (Jacobi)"] = simulate_ssp(ssp, ssp_stop, step)
        try:
            rows["libcosim 0.0.6 via libcosimpy (Jacobi)"] = libcosim(ssp, ssp_stop, step, max(1, a.repeat // 2))
        except ImportError as e:
            rows["libcosim"] = {"error": str(e)}
        calls = calls_per_step(gs)
    base = rows["twinbench, FMUs (Gauss-Seidel)"]["wall"]
    native = rows["twinbench, native models (Gauss-Seidel)"]
    native_per_step = native["wall"] / native["steps"]
    for name, r in rows.items():
        if "error" in r:
            continue
        r["ratio"] = r["wall"] / base
        r["ns_per_step"] = r["wall"] * 1e9 / r["steps"]
        r["overhead_ns_per_call"] = (r["wall"] / r["steps"] - native_per_step) * 1e9 / calls
    m = machine()
    result = {"date": datetime.date.today().isoformat(), "machine": m, "fmu_calls_per_step": calls, "rows": rows}
    if a.json:
        print(json.dumps(result, indent=1))
        return 0
    print(f"Date {result['date']}; machine: {m['cpu']}, nproc {m['nproc']}, {m['os']}, Python {m['python']}.")
    print(f"One lap of systems/rls_v.toml at 1 ms; {calls} FMU calls per macro step in twinbench's master.\n")
    print("| master | wall time per lap [s] | ratio to twinbench (FMUs) | ns per macro step | overhead per FMU call [ns] | runs |")
    print("|---|---:|---:|---:|---:|---:|")
    for name, r in rows.items():
        if "error" in r:
            print(f"| {name} | not available: {r['error']} | | | | |")
            continue
        print(f"| {name} | {r['wall']:.3f} | {r['ratio']:.2f}x | {r['ns_per_step']:,.0f} | "
              f"{r['overhead_ns_per_call']:,.0f} | {r['runs']} (median {r['median']:.3f} s) |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
