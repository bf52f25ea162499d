#!/usr/bin/env python3
"""How far the intervals and the model check can be trusted, measured the way a user works:
synthetic laps with a known truth (tools/synthetic_laps.py), each prepared by
`twinbench lap` (the target derived from the measured speed, the track given) and fitted by
its own two-step study and joint refinement (`twinbench optimize`), never with the truth's
inputs. Prints, per parameter: coverage of the scatter interval and of the interval with
the model's share, the spread of the standardised errors (sd of z), the mean relative
error; and how often the model check fired.

    tools/calibrate.py --kind twin --circuits own,spielberg --laps 10 --out target/calibration/twin
    tools/calibrate.py --kind car --circuits own,spielberg,random:3 --laps 4 --out target/calibration/car

`--jobs` studies run side by side (each on one thread); `--generations` per step (12: the
answer is the joint refinement's, which starts wherever the steps end). Results are kept
per lap in OUT/<circuit>-<seed>/ and summed up in OUT/summary.json; a lap already fitted is
not fitted again (delete its folder to redo it).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TB = Path(os.environ.get("TWINBENCH_EXE", ROOT / "target" / "release" / "twinbench"))
PY = sys.executable


def fit(kind: str, circuit: str, seed: int, out: Path, generations: int, extra: list, chassis=None) -> dict:
    d = out / f"{circuit.replace(':', '')}-{seed}"
    done = d / "fit.json"
    if done.exists():
        return json.loads(done.read_text())
    d.mkdir(parents=True, exist_ok=True)
    subprocess.run([PY, str(ROOT / "tools" / "synthetic_laps.py"), kind, "--circuit", circuit, "--seed", str(seed),
                    "--out", str(d)], check=True, capture_output=True)
    lap = d / "lap"
    p = subprocess.run([str(TB), "lap", str(d / "measurement.csv"), "--track", str(d / "track.csv"), "--out", str(lap),
                        "--fmus", os.environ.get("TWINBENCH_FMUS", str(ROOT / "target" / "fmu")), *(["--chassis", chassis] if chassis else [])],
                       capture_output=True, text=True)
    if p.returncode != 0:
        return {"error": p.stderr[-2000:], "lap": str(d)}
    p = subprocess.run([str(TB), "optimize", str(lap / "study.toml"), "--json", "--no-report", "--threads", "1",
                        "--generations", str(generations), "--out", str(d / "opt"), "--force", *extra],
                       capture_output=True, text=True)
    if p.returncode != 0:
        return {"error": p.stderr[-2000:], "lap": str(d)}
    result = json.loads(p.stdout)
    truth = json.loads((d / "truth.json").read_text())
    # The car's chassis modes are truths too where the study fits them (--chassis).
    truth_values = dict(truth["truth"])
    truth_values.update({f"vehicle.{k}": v for k, v in truth.get("modes", {}).items()})
    rec = {"lap": str(d), "kind": kind, "circuit": circuit, "seed": seed, "truth": truth_values,
           "parameters": result["joint"]["parameters"], "model_check": result["joint"].get("model_check"),
           "intervals": {k: v for k, v in (result.get("joint_intervals") or {}).items() if k != "parameters"},
           "joint_intervals_parameters": (result.get("joint_intervals") or {}).get("parameters", []),
           "bootstrap": result["joint"].get("bootstrap"),
           "simulations": result["simulations"], "wall_seconds": result["wall_seconds"]}
    done.write_text(json.dumps(rec, indent=1))
    return rec


def summarise(recs: list) -> dict:
    names = [p["name"] for p in recs[0]["parameters"]]
    table = {}
    for n in names:
        rows = []
        for r in recs:
            if n not in r["truth"]:
                continue
            p = next(p for p in r["parameters"] if p["name"] == n)
            truth = r["truth"][n]
            iv = p.get("interval")
            se = p.get("std_error")
            if se is None:
                se = next((q.get("std_error") for q in r.get("joint_intervals_parameters", []) if q["name"] == n), None)
            lo, hi = (iv[0] if iv and iv[0] is not None else -math.inf,
                      iv[1] if iv and iv[1] is not None else math.inf) if iv else (math.nan, math.nan)
            ivm = p.get("interval_with_model")
            lom, him = (ivm[0] if ivm and ivm[0] is not None else -math.inf,
                        ivm[1] if ivm and ivm[1] is not None else math.inf) if ivm else (lo, hi)
            rows.append(dict(est=p["after"], truth=truth, se=se, inside=lo <= truth <= hi,
                             inside_model=lom <= truth <= him,
                             z=(p["after"] - truth) / se if se else math.nan,
                             rel=(p["after"] - truth) / truth,
                             width=(hi - lo) / abs(truth) if iv else math.nan,
                             width_model=(him - lom) / abs(truth) if ivm else math.nan))
        # The bootstrap where it ran: its standard error over the sandwich's, and whether its
        # percentile interval holds the truth.
        boots = [next((q for q in r["bootstrap"]["parameters"] if q["name"] == n), None)
                 for r in recs if r.get("bootstrap")]
        boots = [b for b in boots if b and b.get("ratio") is not None and b.get("interval")]
        zs = [x["z"] for x in rows if not math.isnan(x["z"])]
        mz = sum(zs) / len(zs) if zs else math.nan
        table[n] = dict(
            n=len(rows), inside=sum(x["inside"] for x in rows), inside_model=sum(x["inside_model"] for x in rows),
            sd_z=math.sqrt(sum((z - mz) ** 2 for z in zs) / max(len(zs) - 1, 1)) if zs else math.nan,
            mean_z=mz, mean_rel_error=sum(x["rel"] for x in rows) / len(rows),
            mean_width=sum(x["width"] for x in rows) / len(rows),
            mean_width_model=sum(x["width_model"] for x in rows) / len(rows),
            bootstrap_laps=len(boots),
            bootstrap_ratio_median=sorted(b["ratio"] for b in boots)[len(boots) // 2] if boots else math.nan,
            bootstrap_inside=sum(b["interval"][0] <= r["truth"][n] <= b["interval"][1]
                                 for b, r in zip(boots, [r for r in recs if r.get("bootstrap")])),
        )
    fired = [r["model_check"]["discrepancy"] for r in recs if r.get("model_check")]
    return {"laps": len(recs), "parameters": table,
            "model_check_fired": sum(fired), "model_check_laps": len(fired)}


def main(argv=None):
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("--kind", choices=["twin", "car"], required=True)
    a.add_argument("--circuits", default="own,spielberg")
    a.add_argument("--laps", type=int, default=10, help="laps per circuit")
    a.add_argument("--first-seed", type=int, default=1)
    a.add_argument("--generations", type=int, default=12)
    a.add_argument("--jobs", type=int, default=2)
    a.add_argument("--out", type=Path, required=True)
    a.add_argument("--chassis", default=None, help="second-order: the studies fit the pitch and roll modes too")
    a.add_argument("--bootstrap", type=int, default=0, metavar="N",
                   help="a moving-block bootstrap of every answer with N refits (its standard error against the sandwich's)")
    args = a.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    extra = ["--bootstrap", str(args.bootstrap)] if args.bootstrap else []
    jobs = [(c, s) for c in args.circuits.split(",") for s in range(args.first_seed, args.first_seed + args.laps)]
    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
        recs = list(pool.map(lambda cs: fit(args.kind, cs[0], cs[1], args.out, args.generations, extra, args.chassis),
                             jobs))
    bad = [r for r in recs if "error" in r]
    for r in bad:
        print(f"failed: {r['lap']}: {r['error']}", file=sys.stderr)
    good = [r for r in recs if "error" not in r]
    s = summarise(good)
    (args.out / "summary.json").write_text(json.dumps(s, indent=1))
    print(f"{s['laps']} laps ({len(bad)} failed); model check fired on {s['model_check_fired']} of {s['model_check_laps']}")
    print("| parameter | scatter interval holds the truth | with the model's share | sd(z) | mean z | mean rel. error | mean width | width with model |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for n, t in s["parameters"].items():
        print(f"| {n} | {t['inside']}/{t['n']} | {t['inside_model']}/{t['n']} | {t['sd_z']:.2f} | {t['mean_z']:+.2f} | "
              f"{100 * t['mean_rel_error']:+.2f} % | {100 * t['mean_width']:.1f} % | {100 * t['mean_width_model']:.1f} % |")
    if any(t["bootstrap_laps"] for t in s["parameters"].values()):
        print()
        print("| parameter | bootstrap SE / sandwich SE (median) | bootstrap percentile interval holds the truth |")
        print("|---|---:|---:|")
        for n, t in s["parameters"].items():
            print(f"| {n} | {t['bootstrap_ratio_median']:.2f} | {t['bootstrap_inside']}/{t['bootstrap_laps']} |")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
