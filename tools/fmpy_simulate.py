#!/usr/bin/env python3
"""Simulate one FMU in FMPy's co-simulation master (or, with --model-exchange, FMPy's
Model Exchange loop with its CVode solver) and write every output at every communication
point, for comparison with twinbench.

Usage: fmpy_simulate.py FMU OUT.csv --stop T --step H [--start T0] [--input IN.csv]
                        [--set NAME=VALUE ...] [--tolerance RTOL] [--model-exchange]

OUT.csv: a header (time, then the outputs in model order), then one row per communication
point; Real values as repr() (shortest round trip), Booleans as 0/1, Strings quoted."""
import argparse
import csv
import math

import numpy as np
from fmpy import read_model_description, simulate_fmu


def read_input(path, md):
    """A time-based input file as FMPy's structured array, typed after the FMU's inputs."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    names = rows[0]
    types = {v.name: v.type for v in md.modelVariables}
    keep = [i for i, n in enumerate(names) if i == 0 or n in types]
    dtype = []
    for i in keep:
        n = names[i]
        t = types.get(n, "Real")
        if i == 0:
            dtype.append((n, np.double))
        elif t in ("Boolean",):
            dtype.append((n, np.bool_))
        elif t in ("Integer", "Enumeration", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32",
                   "Int64", "UInt64"):
            dtype.append((n, np.int64 if t != "UInt64" else np.uint64))
        else:
            dtype.append((n, np.double))
    data = [tuple(int(r[i]) if dtype[k][1] in (np.int64, np.uint64) else float(r[i])
                  for k, i in enumerate(keep)) for r in rows[1:] if r]
    return np.array(data, dtype=dtype)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("fmu")
    p.add_argument("out")
    p.add_argument("--stop", type=float, required=True)
    p.add_argument("--step", type=float, required=True)
    p.add_argument("--start", type=float, default=0.0)
    p.add_argument("--input")
    p.add_argument("--set", action="append", default=[])
    p.add_argument("--model-exchange", action="store_true",
                   help="FMPy's Model Exchange loop with solver='CVode' (output interval = step)")
    p.add_argument("--record-events", action="store_true",
                   help="with --model-exchange: also the rows FMPy records before and after each event")
    p.add_argument("--tolerance", type=float, default=None,
                   help="the relative tolerance (default: the FMU's DefaultExperiment's, else FMPy's)")
    a = p.parse_args()
    md = read_model_description(a.fmu)
    # Binary and Clock values have no column in twinbench.
    outputs = [v.name for v in md.modelVariables
               if v.causality == "output" and v.type not in ("Binary", "Clock")]
    start_values = {}
    for s in a.set:
        k, v = s.split("=", 1)
        start_values[k] = float(v) if v.replace(".", "", 1).replace("e", "", 1).lstrip("-").isdigit() else v
    extra = {"solver": "CVode", "record_events": a.record_events} if a.model_exchange else {}
    res = simulate_fmu(a.fmu, fmi_type="ModelExchange" if a.model_exchange else "CoSimulation",
                       start_time=a.start, stop_time=a.stop,
                       output_interval=a.step, output=outputs, start_values=start_values,
                       relative_tolerance=a.tolerance,
                       input=read_input(a.input, md) if a.input else None, **extra)
    with open(a.out, "w", newline="") as f:
        w = csv.writer(f)
        # An FMI 3.0 array is one column per element, name[i] or name[i,j] (1-based).
        header = []
        for name in res.dtype.names:
            shape = res.dtype[name].shape
            if shape:
                header += [f"{name}[{','.join(str(i + 1) for i in idx)}]" for idx in np.ndindex(shape)]
            else:
                header.append(name)
        w.writerow(header)
        for row in res:
            out = []
            flat = []
            for x in row:
                if isinstance(x, np.ndarray):
                    flat.extend(x.flatten().tolist())
                else:
                    flat.append(x)
            for x in flat:
                if isinstance(x, (bytes, str)):
                    out.append(x.decode() if isinstance(x, bytes) else x)
                elif isinstance(x, (bool, np.bool_)):
                    out.append(int(x))
                elif isinstance(x, (float, np.floating)):
                    out.append(repr(float(x)))
                else:
                    out.append(int(x))
            w.writerow(out)


if __name__ == "__main__":
    main()
