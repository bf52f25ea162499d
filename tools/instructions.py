#!/usr/bin/env python3
"""Instruction counts (callgrind), the stable measure of docs/benchmark.md: machines and
their load change wall times, not the instructions a run executes.

- start-up: `twinbench run` of the RLS/v bench stopped after one 1 ms step, twice in a row
  (the second finds the FMUs already unpacked);
- lap loop: instructions per macro step of a whole Spielberg lap, i.e. (lap − one-step
  run) / (steps − 1), masters, FMI calls and models included;
- start-up of a second run on a system without Landlock (isolated workers cannot be kept
  from writing the store, so the host checks each library against its archive).

valgrind (3.19) does not know Landlock's system calls: under it twinbench would find no
Landlock and take the last path every time. The first measures set
TWINBENCH_WORKER_SANDBOX=assume (the host takes workers as sandboxed without asking the
kernel, as it finds them natively on this machine); the last sets it to `off`.

Usage: tools/instructions.py [--json] [--fmi 3] [--set instance.variable=value ...]   (needs valgrind;
  run tools/benchmark.sh first, or `cargo build --release` and `target/release/twinbench
  pack`). `--set` changes a parameter in every measured run, e.g.
  `--set vehicle.chassis_model=second_order` for the second-order chassis' cost.
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TB = os.path.join(ROOT, "target", "release", "twinbench")
sys.path.insert(0, os.path.join(ROOT, "tools"))
from benchmark import system_variant  # noqa: E402


def callgrind(system, tmp, env, sets=()):
    out = os.path.join(tmp, "callgrind.out")
    args = [a for s in sets for a in ("--set", s)]
    p = subprocess.run(
        ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", TB, "run", system, "--json", *args],
        capture_output=True, text=True, env=env,
    )
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-2000:])
    total = int(re.search(r"Collected : (\d+)", p.stderr).group(1))
    steps = json.loads(p.stdout)["steps"]
    os.remove(out)
    return total, steps


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--fmi", type=int, choices=(2, 3), default=2,
                    help="the bench of the models' FMI 2.0 FMUs (default) or FMI 3.0 FMUs "
                         "(pack them first: twinbench pack --fmi 2,3 -o target/fmu)")
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a parameter for every measured run (as twinbench run --set)")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ)
        # A store of unpacked FMUs of this measurement's own: the first run fills it.
        env["TWINBENCH_CACHE"] = os.path.join(tmp, "unpacked")
        env["TWINBENCH_WORKER_SANDBOX"] = "assume"
        short = system_variant(tmp, stop=0.001, fmi=a.fmi)
        first, _ = callgrind(short, tmp, env, a.set)
        second, one = callgrind(short, tmp, env, a.set)
        lap, steps = callgrind(system_variant(tmp, fmi=a.fmi), tmp, env, a.set)
        env["TWINBENCH_WORKER_SANDBOX"] = "off"
        no_landlock, _ = callgrind(short, tmp, env, a.set)
    per_step = (lap - second) / (steps - one)
    result = {
        "startup_first_run": first,
        "startup_second_run": second,
        "lap_total": lap,
        "lap_steps": steps,
        "lap_loop_per_step": per_step,
        "startup_second_run_without_landlock": no_landlock,
    }
    if a.json:
        print(json.dumps(result, indent=1))
        return 0
    print("| measure (callgrind) | instructions |")
    print("|---|---:|")
    print(f"| start-up, first `run` (one 1 ms step) | {first / 1e6:,.1f} M |")
    print(f"| start-up, second `run` on the same FMUs | {second / 1e6:,.1f} M |")
    print(f"| whole lap ({steps:,} steps) | {lap / 1e6:,.1f} M |")
    print(f"| lap loop, per macro step | {per_step:,.0f} |")
    print(f"| start-up, second `run`, no Landlock (libraries checked against the archives) | {no_landlock / 1e6:,.1f} M |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
