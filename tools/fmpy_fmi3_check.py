#!/usr/bin/env python3
"""An FMI 3.0 FMU of twinbench against its FMI 2.0 twin in FMPy: validation of the 3.0
one, then each simulated alone for 2 s at its default step, every output compared bit for
bit.

Usage: fmpy_fmi3_check.py FMU2 FMU3 [FMU2 FMU3 ...]; prints one JSON object per pair and
exits non-zero when a 3.0 FMU has validation problems or differs from its 2.0 twin."""
import json
import sys

import numpy as np
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu


def check(fmu2, fmu3):
    r = {"fmi2": fmu2, "fmi3": fmu3}
    r["problems"] = [str(p) for p in validate_fmu(fmu3)]
    md3 = read_model_description(fmu3)
    r["fmi_version"] = md3.fmiVersion
    res2 = simulate_fmu(fmu2, fmi_type="CoSimulation", stop_time=2.0, output_interval=1e-3)
    res3 = simulate_fmu(fmu3, fmi_type="CoSimulation", stop_time=2.0, output_interval=1e-3)
    names = [n for n in res2.dtype.names if n != "time"]
    missing = [n for n in names if n not in res3.dtype.names]
    differ = []
    for n in names:
        if n in missing:
            continue
        a, b = np.asarray(res2[n]), np.asarray(res3[n])
        if a.dtype.kind == "f":
            same = a.shape == b.shape and np.array_equal(a.view(np.uint64), b.astype(np.float64).view(np.uint64))
        else:
            same = a.shape == b.shape and np.array_equal(a, b)
        if not same:
            differ.append(n)
    r["rows"] = [len(res2), len(res3)]
    r["signals"] = len(names)
    r["missing"] = missing
    r["differ"] = differ
    r["bitwise_equal"] = not missing and not differ and len(res2) == len(res3)
    return r


def main():
    args = sys.argv[1:]
    ok = True
    for fmu2, fmu3 in zip(args[::2], args[1::2]):
        try:
            r = check(fmu2, fmu3)
        except Exception as e:  # report and go on with the next pair
            r = {"fmi2": fmu2, "fmi3": fmu3, "error": repr(e), "problems": [], "bitwise_equal": False}
        ok = ok and not r["problems"] and r["bitwise_equal"]
        print(json.dumps(r))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
