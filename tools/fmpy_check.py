#!/usr/bin/env python3
"""Validate FMUs with FMPy and simulate each in co-simulation mode.

Usage: fmpy_check.py FMU... ; prints one JSON object per FMU and exits non-zero if any
FMU has validation problems or fails to simulate."""
import json
import math
import sys

from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu


def check(path):
    result = {"fmu": path, "problems": [], "simulated": False}
    result["problems"] = [str(p) for p in validate_fmu(path)]
    md = read_model_description(path)
    de = md.defaultExperiment
    # FMPy keeps the DefaultExperiment attributes as text.
    stop = min(float(de.stopTime) if de and de.stopTime else 1.0, 1.0)
    step = float(de.stepSize) if de and de.stepSize else 1e-3
    res = simulate_fmu(path, fmi_type="CoSimulation", stop_time=stop, step_size=step,
                       output_interval=step * 10)
    result["rows"] = len(res)
    result["stop_time"] = float(res["time"][-1])
    outputs = [n for n in res.dtype.names if n != "time"]
    finite = all(math.isfinite(float(res[n][-1])) for n in outputs)
    result["outputs"] = outputs
    result["finite"] = finite
    result["simulated"] = abs(result["stop_time"] - stop) < 1e-9 and finite
    return result


def main():
    ok = True
    for path in sys.argv[1:]:
        try:
            r = check(path)
        except Exception as e:  # report and go on with the next FMU
            r = {"fmu": path, "error": repr(e), "problems": [], "simulated": False}
        ok = ok and not r["problems"] and r["simulated"]
        print(json.dumps(r))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
