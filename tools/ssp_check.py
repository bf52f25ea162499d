#!/usr/bin/env python3
"""Validate an SSP exported by `twinbench export-ssp` and run it in FMPy and libcosim.

Usage:
  ssp_check.py BENCH.ssp [--stop T] [--fmpy] [--libcosim] [--compare twinbench.csv] [--json]

- validation: SystemStructure.ssd against the SSP 1.0 schema FMPy ships
  (fmpy/ssp/schema/SystemStructureDescription.xsd), with lxml;
- FMPy: `fmpy.ssp.simulate_ssp` with the parameter values of the components'
  ParameterBindings (simulate_ssp applies only a parameter set it is given, so the
  bindings read by `read_ssd` are passed as one, names prefixed by the component);
- libcosim: `libcosimpy` (`CosimExecution.from_ssp_file`, the step from the OSP
  annotation), every compared signal observed by a time-series observer;
- comparison with twinbench's CSV of the same system in Jacobi mode: every signal both
  sides have, matched by step number k = t/h; max absolute and relative difference.
The step and stop time default to the SSD's annotations / DefaultExperiment.
"""
import argparse
import csv
import json
import math
import os
import sys
import time
import zipfile

from lxml import etree

TB_NS = "https://github.com/twinbench/ssp"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"


def validate(ssp):
    import fmpy.ssp
    schema_file = os.path.join(os.path.dirname(fmpy.ssp.__file__), "schema", "SystemStructureDescription.xsd")
    schema = etree.XMLSchema(file=schema_file)
    with zipfile.ZipFile(ssp) as z:
        root = etree.parse(z.open("SystemStructure.ssd")).getroot()
        names = z.namelist()
    ok = schema.validate(root)
    problems = [f"line {e.line}: {e.message}" for e in schema.error_log]
    # Every component's source must be in the archive.
    for c in root.iter(f"{{{SSD}}}Component"):
        if c.get("source") not in names:
            problems.append(f"component {c.get('name')}: {c.get('source')} is not in the archive")
            ok = False
    exp = root.find(f"{{{SSD}}}DefaultExperiment")
    tb = root.find(f".//{{{TB_NS}}}Experiment")
    info = {
        "schema": os.path.relpath(schema_file, os.path.dirname(os.path.dirname(fmpy.ssp.__file__))),
        "valid": ok and not problems,
        "problems": problems,
        "start": float(exp.get("startTime", 0.0)) if exp is not None else 0.0,
        "stop": float(exp.get("stopTime")) if exp is not None and exp.get("stopTime") else None,
        "step": float(tb.get("stepSize")) if tb is not None else None,
    }
    return info


def run_fmpy(ssp, stop, step):
    from fmpy.ssp.ssd import read_ssd, ParameterSet, Parameter, find_components
    from fmpy.ssp.simulation import simulate_ssp

    ssd = read_ssd(ssp)  # validates again, with FMPy's own reader
    ps = ParameterSet(name="bindings")
    for comp in find_components(ssd.system):
        for b in comp.parameterBindings:
            for pset in b.parameterValues:
                for p in pset.parameters:
                    ps.parameters.append(Parameter(name=f"{comp.name}.{p.name}", type=p.type, value=p.value, unit=p.unit))
    wall = time.perf_counter()
    res = simulate_ssp(ssp, stop_time=stop, step_size=step, parameter_set=ps)
    wall = time.perf_counter() - wall
    # Row i is labelled with the step's start time; its values are those after the step.
    steps = [int(round(t / step)) + 1 for t in res["time"]]
    cols = {n: [float(x) for x in res[n]] for n in res.dtype.names if n != "time"}
    return {"wall_time": wall, "steps": len(steps), "k": steps, "cols": cols}


def run_libcosim(ssp, stop, step, signals):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimLogging import log_output_level, CosimLogLevel

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_ssp_file(ssp)
    n_steps = int(round(stop / step))
    slaves = {}
    for s in ex.slave_infos():
        name = s.name.decode() if isinstance(s.name, bytes) else s.name
        slaves[name] = s.index
    observed = []
    obs = CosimObserver.create_time_series(buffer_size=n_steps + 10)
    ex.add_observer(obs)  # before the series are started (libcosim needs the slaves)
    for full in signals:
        inst, _, var = full.partition(".")
        if inst not in slaves:
            continue
        for v in ex.slave_variables(slaves[inst]):
            vname = v.name.decode() if isinstance(v.name, bytes) else v.name
            if vname == var:
                kind = {0: CosimVariableType.REAL, 1: CosimVariableType.INTEGER}.get(int(v.type))
                if kind is None:
                    break
                if not obs.start_time_series(slaves[inst], v.reference, kind):
                    raise RuntimeError(f"libcosim cannot observe {full}")
                observed.append((full, slaves[inst], v.reference, kind))
                break
    wall = time.perf_counter()
    ok = ex.simulate_until(int(round(stop * 1e9)))
    wall = time.perf_counter() - wall
    if not ok:
        raise RuntimeError("libcosim simulate_until failed")
    cols, ks = {}, None
    for full, si, vr, kind in observed:
        if kind == CosimVariableType.REAL:
            times, stepnums, vals = obs.time_series_real_samples(si, vr, from_step=0, sample_count=n_steps + 5)
        else:
            times, stepnums, vals = obs.time_series_integer_samples(si, vr, from_step=0, sample_count=n_steps + 5)
        k = [int(round(t * 1e-9 / step)) for t in times]
        cols[full] = [float(x) for x in vals]
        if ks is None:
            ks = k
        elif ks != k:
            raise RuntimeError(f"{full}: sample times differ from the other signals'")
    return {"wall_time": wall, "steps": n_steps, "k": ks or [], "cols": cols}


def read_twinbench_csv(path):
    with open(path) as f:
        r = csv.reader(f)
        names = next(r)
        next(r)
        cols = [[] for _ in names]
        for row in r:
            for i, x in enumerate(row):
                cols[i].append(float(x))
    return dict(zip(names, cols))


def compare(run, ref, step, skip_until=0.0):
    """Per signal on the common steps (k*h >= skip_until): max abs and relative difference
    (relative to the signal's largest magnitude in twinbench's run)."""
    ref_k = {int(round(t / step)): i for i, t in enumerate(ref["time"])}
    pairs = [(j, ref_k[k]) for j, k in enumerate(run["k"]) if k in ref_k and k * step >= skip_until - 1e-12]
    out = {}
    for name, col in run["cols"].items():
        if name not in ref:
            continue
        r = ref[name]
        scale = max((abs(x) for x in r), default=0.0) or 1.0
        d = max((abs(col[j] - r[i]) for j, i in pairs), default=0.0)
        out[name] = {"max_abs": d, "max_rel_to_range": d / scale}
    worst = max(out.items(), key=lambda kv: kv[1]["max_rel_to_range"], default=(None, {"max_rel_to_range": 0.0}))
    return {"points": len(pairs), "signals": out, "worst": worst[0], "worst_rel": worst[1]["max_rel_to_range"]}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("ssp")
    ap.add_argument("--stop", type=float)
    ap.add_argument("--step", type=float)
    ap.add_argument("--fmpy", action="store_true")
    ap.add_argument("--libcosim", action="store_true")
    ap.add_argument("--compare")
    ap.add_argument("--skip-until", type=float, default=0.0,
                    help="also report the comparison from this time on (after the start transient)")
    ap.add_argument("--save", help="write the FMPy result columns to this CSV")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    v = validate(a.ssp)
    out = {"ssp": a.ssp, "validation": v}
    stop = a.stop or v["stop"]
    step = a.step or v["step"]
    ref = read_twinbench_csv(a.compare) if a.compare else None
    signals = [n for n in ref if n != "time"] if ref else []
    if a.fmpy:
        r = run_fmpy(a.ssp, stop, step)
        out["fmpy"] = {"wall_time": r["wall_time"], "steps": r["steps"]}
        if ref:
            out["fmpy"]["compare"] = compare(r, ref, step)
            if a.skip_until:
                out["fmpy"]["compare_after"] = compare(r, ref, step, a.skip_until)
        if a.save:
            names = list(r["cols"])
            with open(a.save, "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["time"] + names)
                w.writerow([""] * (len(names) + 1))  # units row, as twinbench's CSV has
                for j, k in enumerate(r["k"]):
                    w.writerow([repr(k * step)] + [repr(r["cols"][n][j]) for n in names])
    if a.libcosim:
        try:
            r = run_libcosim(a.ssp, stop, step, signals or ["vehicle.v"])
            out["libcosim"] = {"wall_time": r["wall_time"], "steps": r["steps"]}
            if ref:
                out["libcosim"]["compare"] = compare(r, ref, step)
                if a.skip_until:
                    out["libcosim"]["compare_after"] = compare(r, ref, step, a.skip_until)
        except ImportError as e:
            out["libcosim"] = {"error": f"libcosimpy is not installed: {e}"}
    if a.json:
        print(json.dumps(out, indent=1))
    else:
        print(f"schema valid   {v['valid']} {v['problems'][:5]}")
        for tool in ("fmpy", "libcosim"):
            if tool in out:
                t = out[tool]
                if "error" in t:
                    print(f"{tool:9} {t['error']}")
                    continue
                print(f"{tool:9} {t['steps']} steps in {t['wall_time']:.2f} s")
                for key in ("compare", "compare_after"):
                    if key in t:
                        c = t[key]
                        print(f"  {key}: {c['points']} points, worst {c['worst']} {c['worst_rel']:.3e} (of range)")
    return 0 if v["valid"] else 1


if __name__ == "__main__":
    sys.exit(main())
