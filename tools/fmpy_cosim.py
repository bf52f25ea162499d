#!/usr/bin/env python3
"""Run a twinbench system file with FMPy's FMU classes as the co-simulation master.

An independent master for cross-validation (docs/cross_validation.md): it reads the same
system TOML (tomllib) and drives the same FMU files through `fmpy.fmi2.FMU2Slave`,
mirroring twinbench's master algorithm step for step:

- stepping order: `experiment.order`, else a topological order of the connections
  (sources before consumers), ties and cycles broken by declaration order;
- instantiate, fmi2SetupExperiment(start, stop if fixed), parameters one call each,
  fmi2EnterInitializationMode; then sweeps in stepping order (inputs from the current
  signals, outputs read) until every exchanged signal is bitwise unchanged (at most 50),
  then per instance in order: inputs, fmi2ExitInitializationMode, outputs;
- integer ticks t_k = start + k*h (the last step shortened to a fixed stop time);
- each instance's inputs set in one call per type, converted by `to = scale*from + offset`
  from the FMUs' unit definitions;
- Gauss-Seidel: per instance inputs, step, outputs; Jacobi: all inputs gathered first,
  all steps, then all outputs;
- stop at a fixed time or when the lap signal reaches `lap_count`; record every
  `decimation`-th step, and the last step of a run with a fixed stop time.

`--init zero --time-base sum --algorithm jacobi` instead reproduces FMPy's `simulate_ssp`
semantics (no exchange in initialisation: inputs keep their start values and the first
step sees every connected input at 0.0; time accumulated by `t += h`; every step recorded)
to explain the SSP comparison.

Usage:
  fmpy_cosim.py SYSTEM.toml [--algorithm gauss-seidel|jacobi] [--stop T|lap]
                [--set inst.var=value ...] [--out result.csv]
                [--compare twinbench.csv] [--json]
Prints a JSON summary with --json (order, steps, wall time, and the comparison: max
absolute and relative difference per signal).
"""
import argparse
import csv
import json
import math
import os
import sys
import time

try:
    import tomllib
except ImportError:  # Python < 3.11
    import tomli as tomllib

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


# twinbench's master algorithms and stop operators (crates/cosim: Algorithm::ALL, Op::ALL);
# tests/stop_condition_parsers.rs checks that these and parse_condition agree with Rust's.
ALGORITHMS = ("gauss-seidel", "jacobi")
OPS = {">=": lambda x, t: x >= t, "<=": lambda x, t: x <= t, ">": lambda x, t: x > t, "<": lambda x, t: x < t}


def holds(condition, x):
    """Whether `signal OP threshold` holds for the signal's value x."""
    _, op, threshold = condition
    return OPS[op](x, threshold)


def parse_condition(text):
    """`instance.variable OP number` as (signal, op, threshold), or None: the rules of
    twinbench's Condition::parse (the longer of two operators sharing a start first; the
    first occurrence splits; a finite number as Rust parses one)."""
    for op in sorted(OPS, key=len, reverse=True):
        a, found, b = text.partition(op)
        if not found:
            continue
        signal, number = a.strip(), b.strip()
        # Rust's f64 parser takes no underscores and no digits other than ASCII ones.
        if "_" in number or not number or not number.isascii():
            return None
        try:
            threshold = float(number)
        except ValueError:
            return None
        first, _, rest = signal.partition(".")
        if not first or not rest or not math.isfinite(threshold):
            return None
        return (signal, op, threshold)
    return None


class Error(Exception):
    pass


def split_name(s):
    a, _, b = s.strip().partition(".")
    if not a or not b:
        raise Error(f"'{s}' is not of the form instance.variable")
    return a, b


def unit_of(md, v):
    if v.unit is not None:
        return v.unit.name if hasattr(v.unit, "name") else v.unit
    if v.declaredType is not None and getattr(v.declaredType, "unit", None):
        u = v.declaredType.unit
        return u.name if hasattr(u, "name") else u
    return None


def unit_def(md, name):
    for u in md.unitDefinitions:
        if u.name == name and u.baseUnit is not None:
            b = u.baseUnit
            dims = tuple(int(getattr(b, k) or 0) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad"))
            return dims, float(b.factor or 1.0), float(b.offset or 0.0)
    return None


def conversion(from_md, from_unit, to_md, to_unit):
    """(scale, offset) as twinbench computes it: SI = factor*value + offset on both sides."""
    if from_unit is None or to_unit is None or from_unit == to_unit:
        return 1.0, 0.0
    a, b = unit_def(from_md, from_unit), unit_def(to_md, to_unit)
    if a is None or b is None:
        raise Error(f"units '{from_unit}' and '{to_unit}' differ and the FMUs do not define them")
    if a[0] != b[0]:
        raise Error(f"incompatible units '{from_unit}' and '{to_unit}'")
    return a[1] / b[1], (a[2] - b[2]) / b[1]


class Unit:
    """One FMU instance and its exchange tables."""

    def __init__(self, name, fmu_path, ports, md, unzipdir):
        self.name = name
        self.fmu_path = fmu_path
        self.ports = ports
        self.md = md
        self.unzipdir = unzipdir
        self.vars = {v.name: v for v in md.modelVariables}
        self.slave = None
        # (vr, signal slot, scale, offset) per type
        self.inputs = {"Real": [], "Integer": [], "Boolean": []}
        self.outputs = {"Real": [], "Integer": [], "Boolean": []}
        self.params = []  # (vr, type, value)

    def variable(self, name):
        fmu_name = self.ports.get(name, name)
        v = self.vars.get(fmu_name)
        if v is None:
            raise Error(f"unknown variable '{self.name}.{fmu_name}' ({self.fmu_path})")
        return v

    def finish_tables(self):
        self.in_vr = {t: [e[0] for e in l] for t, l in self.inputs.items()}
        self.out_vr = {t: [e[0] for e in l] for t, l in self.outputs.items()}

    def gather(self, signals):
        self.pending = {
            "Real": [sc * signals[s] + off for _, s, sc, off in self.inputs["Real"]],
            "Integer": [int(round(signals[s])) for _, s, _, _ in self.inputs["Integer"]],
            "Boolean": [signals[s] != 0.0 for _, s, _, _ in self.inputs["Boolean"]],
        }

    def set_inputs(self):
        f = self.slave
        if self.in_vr["Real"]:
            f.setReal(self.in_vr["Real"], self.pending["Real"])
        if self.in_vr["Integer"]:
            f.setInteger(self.in_vr["Integer"], self.pending["Integer"])
        if self.in_vr["Boolean"]:
            f.setBoolean(self.in_vr["Boolean"], self.pending["Boolean"])

    def get_outputs(self, signals, names):
        f = self.slave
        if self.out_vr["Real"]:
            vals = f.getReal(self.out_vr["Real"])
            for (_, s, _, _), x in zip(self.outputs["Real"], vals):
                if not math.isfinite(x):
                    raise Error(f"{names[s]} is not finite ({x}) after the step of '{self.name}'")
                signals[s] = x
        if self.out_vr["Integer"]:
            for (_, s, _, _), x in zip(self.outputs["Integer"], f.getInteger(self.out_vr["Integer"])):
                signals[s] = float(x)
        if self.out_vr["Boolean"]:
            for (_, s, _, _), x in zip(self.outputs["Boolean"], f.getBoolean(self.out_vr["Boolean"])):
                signals[s] = 1.0 if x else 0.0


def vtype(v):
    """The exchange table a variable goes into: FMI 2.0's base types (an FMI 3.0 Float64 is
    a Real, an Int32 or an Enumeration an Integer)."""
    return {"Enumeration": "Integer", "Float64": "Real", "Int32": "Integer"}.get(v.type, v.type)


class Slave3:
    """FMPy's FMU3Slave behind the FMI 2.0 calls this script makes: Reals are Float64, an
    Enumeration is got and set as Int64, other Integers as Int32; the experiment goes to
    fmi3EnterInitializationMode."""

    def __init__(self, md, unzipdir, name):
        from fmpy.fmi3 import FMU3Slave
        self.f = FMU3Slave(guid=md.guid, unzipDirectory=unzipdir,
                           modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.enums = {v.valueReference for v in md.modelVariables if v.type == "Enumeration"}
        self.start, self.stop = 0.0, None

    def instantiate(self, loggingOn=False):
        self.f.instantiate(loggingOn=loggingOn)

    def setupExperiment(self, startTime, stopTime):
        self.start, self.stop = startTime, stopTime

    def enterInitializationMode(self):
        self.f.enterInitializationMode(startTime=self.start, stopTime=self.stop)

    def exitInitializationMode(self):
        self.f.exitInitializationMode()

    def setReal(self, vr, values):
        self.f.setFloat64(vr, values)

    def getReal(self, vr):
        return self.f.getFloat64(vr)

    def setInteger(self, vr, values):
        for r, x in zip(vr, values):
            (self.f.setInt64 if r in self.enums else self.f.setInt32)([r], [x])

    def getInteger(self, vr):
        return [(self.f.getInt64 if r in self.enums else self.f.getInt32)([r])[0] for r in vr]

    def setBoolean(self, vr, values):
        self.f.setBoolean(vr, values)

    def getBoolean(self, vr):
        return self.f.getBoolean(vr)

    def doStep(self, currentCommunicationPoint, communicationStepSize):
        self.f.doStep(currentCommunicationPoint, communicationStepSize)

    def terminate(self):
        self.f.terminate()

    def freeInstance(self):
        self.f.freeInstance()


class System:
    def __init__(self, path, overrides=None, algorithm=None, stop=None, order=None):
        with open(path, "rb") as f:
            self.file = tomllib.load(f)
        base = os.path.dirname(os.path.abspath(path))
        sysf = self.file
        if sysf.get("replay"):
            raise Error("replayed measurement channels are not supported by this script")
        if sysf.get("preload"):
            raise Error("preloaded libraries are not supported by this script")
        exp = dict(sysf["experiment"])
        if algorithm:
            exp["algorithm"] = algorithm
        if stop is not None:
            exp["stop"] = stop
        if order:
            exp["order"] = order
        self.exp = exp
        self.start = float(exp.get("start", 0.0))
        self.h = float(exp["step"])
        # stop: a time, a condition "signal >= value" (or <=, >, <), or the older "lap"
        # (lap_signal >= lap_count).
        self.stop = exp["stop"]
        self.condition = None
        if isinstance(self.stop, str):
            if self.stop == "lap":
                if "lap_signal" not in exp:
                    raise Error('stop = "lap" needs lap_signal')
                self.condition = (exp["lap_signal"], ">=", float(exp.get("lap_count", 1.0)))
            else:
                self.condition = parse_condition(self.stop)
                if self.condition is None:
                    raise Error(f"experiment.stop: not a time or a condition: {self.stop!r}")
        self.max_time = float(exp.get("max_time", 600.0))
        self.algorithm = exp.get("algorithm", "gauss-seidel")
        if self.algorithm not in ALGORITHMS:
            raise Error(f"unknown algorithm {self.algorithm}")
        fmus = {k: (p if os.path.isabs(p) else os.path.join(base, p)) for k, p in sysf["fmus"].items()}
        self.unzipdirs = {}
        mds = {}
        for k, p in fmus.items():
            mds[k] = read_model_description(p, validate=False)
            self.unzipdirs[k] = extract(p)
        self.units = []
        for inst in sysf.get("instance", []):
            k = inst["fmu"]
            self.units.append(Unit(inst["name"], fmus[k], inst.get("ports", {}), mds[k], self.unzipdirs[k]))
        self.index = {u.name: i for i, u in enumerate(self.units)}
        # Signal slots: one per distinct source (instance, value reference).
        self.slots = {}
        self.names = []

        def slot(full):
            u, var = split_name(full)
            if u not in self.index:
                raise Error(f"unknown instance '{u}'")
            unit = self.units[self.index[u]]
            v = unit.variable(var)
            key = (self.index[u], v.valueReference)
            if key not in self.slots:
                self.slots[key] = len(self.names)
                self.names.append(full)
                unit.outputs[vtype(v)].append((v.valueReference, self.slots[key], 1.0, 0.0))
            return self.slots[key], unit, v

        deps = [[] for _ in self.units]
        for text in sysf.get("connections", []):
            a, _, b = text.partition("->")
            s, from_unit, from_v = slot(a.strip())
            tu, tv = split_name(b.strip())
            to_unit = self.units[self.index[tu]]
            to_v = to_unit.variable(tv)
            sc, off = conversion(from_unit.md, unit_of(from_unit.md, from_v), to_unit.md, unit_of(to_unit.md, to_v))
            to_unit.inputs[vtype(to_v)].append((to_v.valueReference, s, sc, off))
            fi, ti = self.index[from_unit.name], self.index[tu]
            if fi != ti and fi not in deps[ti]:
                deps[ti].append(fi)
        rec = list(sysf.get("record", {}).get("signals", []))
        if not rec:
            for u in self.units:
                for v in u.md.modelVariables:
                    if v.causality == "output" and v.type != "String":
                        ours = next((o for o, t in u.ports.items() if t == v.name), v.name)
                        rec.append(f"{u.name}.{ours}")
        self.record_names = rec
        self.record_slots = [slot(n)[0] for n in rec]
        self.decimation = int(sysf.get("record", {}).get("decimation", 1))
        self.lap_slot = slot(self.condition[0])[0] if self.condition else None
        params = dict(sysf.get("parameters", {}))
        for o in overrides or []:
            name, _, value = o.partition("=")
            try:
                params[name.strip()] = float(value) if any(c in value for c in ".eE") else int(value)
            except ValueError:
                params[name.strip()] = value.strip()
        for name, value in params.items():
            u, var = split_name(name)
            unit = self.units[self.index[u]]
            v = unit.variable(var)
            if v.type == "Enumeration" and isinstance(value, str):
                # An Enumeration by an item's name, as twinbench takes it.
                items = {i.name: int(i.value) for i in v.declaredType.items}
                if value not in items:
                    sys.exit(f"{name}: '{value}' is not an item of {v.declaredType.name} ({', '.join(items)})")
                value = items[value]
            unit.params.append((v.valueReference, vtype(v), value))
        for u in self.units:
            u.finish_tables()
        # Stepping order (twinbench's rule).
        if exp.get("order"):
            self.order = [self.index[n] for n in exp["order"]]
        else:
            n = len(self.units)
            done, order = [False] * n, []
            while len(order) < n:
                nxt = next((k for k in range(n) if not done[k] and all(done[d] for d in deps[k])), None)
                if nxt is None:
                    nxt = next(k for k in range(n) if not done[k])
                done[nxt] = True
                order.append(nxt)
            self.order = order

    def order_names(self):
        return [self.units[k].name for k in self.order]

    def instantiate(self, fixed_stop):
        for u in self.units:
            md = u.md
            if md.fmiVersion.startswith("3"):
                u.slave = Slave3(md, u.unzipdir, u.name)
            else:
                u.slave = FMU2Slave(guid=md.guid, unzipDirectory=u.unzipdir,
                                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=u.name)
            u.slave.instantiate(loggingOn=False)
            u.slave.setupExperiment(startTime=self.start, stopTime=fixed_stop)
            for vr, ty, value in u.params:
                if ty == "Real":
                    u.slave.setReal([vr], [float(value)])
                elif ty == "Integer":
                    u.slave.setInteger([vr], [int(value)])
                elif ty == "Boolean":
                    u.slave.setBoolean([vr], [bool(value)])

    def initialize(self, signals, init):
        for u in self.units:
            u.slave.enterInitializationMode()
        ordered = [self.units[k] for k in self.order]
        sweeps = 0
        if init == "fixed-point":
            previous = [math.nan] * len(signals)
            for _ in range(50):
                sweeps += 1
                for u in ordered:
                    u.gather(signals)
                    u.set_inputs()
                    u.get_outputs(signals, self.names)
                if all(a == b and math.copysign(1, a) == math.copysign(1, b) for a, b in zip(previous, signals)):
                    break
                previous = list(signals)
            for u in ordered:
                u.gather(signals)
                u.set_inputs()
                u.slave.exitInitializationMode()
                u.get_outputs(signals, self.names)
        else:
            # simulate_ssp: no exchange in initialisation; connectors start at 0.0.
            for u in ordered:
                u.slave.exitInitializationMode()
        return sweeps

    def run(self, init="fixed-point", time_base="ticks"):
        wall = time.perf_counter()
        fixed_stop = None if self.condition else float(self.stop)
        signals = [0.0] * len(self.names)
        # simulate_ssp calls fmi2SetupExperiment without a stop time.
        self.instantiate(fixed_stop if time_base != "sum" else None)
        sweeps = self.initialize(signals, init)
        # simulate_ssp records after each step only.
        rows = [[self.start] + [signals[s] for s in self.record_slots]] if time_base != "sum" else []
        if init == "zero":
            signals = [0.0] * len(self.names)
        start, h = self.start, self.h
        span = (fixed_stop if fixed_stop is not None else start + self.max_time) - start
        full_steps = math.floor(span / h * (1.0 + 1e-12))
        last = span - full_steps * h
        total = full_steps + (1 if last > h * 1e-9 else 0)
        ordered = [self.units[k] for k in self.order]
        jacobi = self.algorithm == "jacobi"
        k, t_end, lap_done = 0, start, False
        t_sum = start
        while (k < total) if time_base != "sum" else (t_sum < start + span):
            if time_base == "ticks":
                t = start + k * h
                step = last if k == full_steps else h
            elif time_base == "ns":
                # libcosim: integer nanoseconds; t and the step size converted to double
                # at each step (the step as the difference of two converted time points).
                hns = int(round(h * 1e9))
                t = (int(round(start * 1e9)) + k * hns) / 1e9
                step = (int(round(start * 1e9)) + (k + 1) * hns) / 1e9 - t
            else:
                # simulate_ssp: time += step_size, steps while time < stop_time.
                t, step = t_sum, h
                t_sum += h
            if jacobi:
                for u in ordered:
                    u.gather(signals)
                for u in ordered:
                    u.set_inputs()
                    u.slave.doStep(currentCommunicationPoint=t, communicationStepSize=step)
                for u in ordered:
                    u.get_outputs(signals, self.names)
            else:
                for u in ordered:
                    u.gather(signals)
                    u.set_inputs()
                    u.slave.doStep(currentCommunicationPoint=t, communicationStepSize=step)
                    u.get_outputs(signals, self.names)
            k += 1
            if time_base != "sum":
                t_end = start + span if (k == total and fixed_stop is not None) else start + k * h
            else:
                t_end = t_sum
            lap_done = self.lap_slot is not None and holds(self.condition, signals[self.lap_slot])
            if k % self.decimation == 0 or (k == total and fixed_stop is not None) or time_base == "sum":
                rows.append([t_end] + [signals[s] for s in self.record_slots])
            if lap_done:
                break
        if fixed_stop is None and not lap_done:
            raise Error(f"the run did not complete within max_time = {self.max_time} s")
        for u in self.units:
            u.slave.terminate()
            u.slave.freeInstance()
        return {
            "steps": k,
            "simulated_time": t_end - start,
            "wall_time": time.perf_counter() - wall,
            "init_sweeps": sweeps,
            "rows": rows,
        }

    def cleanup(self):
        import shutil
        for d in self.unzipdirs.values():
            shutil.rmtree(d, ignore_errors=True)


def write_csv(path, names, rows):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time"] + names)
        for r in rows:
            w.writerow([repr(x) for x in r])


def read_twinbench_csv(path):
    with open(path) as f:
        r = csv.reader(f)
        names = next(r)
        next(r)  # units
        cols = [[] for _ in names]
        for row in r:
            for i, x in enumerate(row):
                cols[i].append(float(x))
    return names, cols


def rel_diff(a, b, scale):
    """|a - b| relative to the larger of |a|, |b| and 1e-12 of the signal's range."""
    d = abs(a - b)
    if d == 0.0:
        return 0.0
    return d / max(abs(a), abs(b), 1e-12 * scale)


def compare(names, rows, ref_names, ref_cols):
    """Per signal: max absolute and relative difference, bitwise equality."""
    if len(rows) != len(ref_cols[0]):
        return {"error": f"{len(rows)} rows here, {len(ref_cols[0])} in the reference"}
    out = {}
    cols = list(zip(*rows))
    for i, n in enumerate(["time"] + names):
        if n not in ref_names:
            continue
        ref = ref_cols[ref_names.index(n)]
        mine = cols[i]
        scale = max((abs(x) for x in ref), default=0.0)
        max_abs = max((abs(a - b) for a, b in zip(mine, ref)), default=0.0)
        max_rel = max((rel_diff(a, b, scale) for a, b in zip(mine, ref)), default=0.0)
        out[n] = {
            "max_abs": max_abs,
            "max_rel": max_rel,
            "bitwise_equal": all(a == b for a, b in zip(mine, ref)),
        }
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("system")
    ap.add_argument("--algorithm", choices=ALGORITHMS)
    ap.add_argument("--stop", help="a time in s, or a condition such as 'vehicle.lap >= 1'")
    ap.add_argument("--order", help="comma-separated instance names")
    ap.add_argument("--set", action="append", default=[], help="instance.variable=value")
    ap.add_argument("--init", choices=["fixed-point", "zero"], default="fixed-point")
    ap.add_argument("--time-base", choices=["ticks", "sum", "ns"], default="ticks",
                    help="sum: t += h while t < stop, every step recorded (simulate_ssp's loop); "
                         "ns: libcosim's integer-nanosecond clock (t and h converted per step)")
    ap.add_argument("--out")
    ap.add_argument("--compare", help="twinbench's CSV of the same run")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    stop = None
    if a.stop is not None:
        try:
            stop = float(a.stop)
        except ValueError:
            stop = a.stop
    try:
        sys_ = System(a.system, a.set, a.algorithm, stop, a.order.split(",") if a.order else None)
        r = sys_.run(a.init, a.time_base)
    except Error as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    summary = {
        "system": a.system,
        "algorithm": sys_.algorithm,
        "order": sys_.order_names(),
        "init": a.init,
        "init_sweeps": r["init_sweeps"],
        "steps": r["steps"],
        "simulated_time": r["simulated_time"],
        "wall_time": r["wall_time"],
        "ns_per_step": r["wall_time"] * 1e9 / max(r["steps"], 1),
        "rows": len(r["rows"]),
    }
    if a.out:
        write_csv(a.out, sys_.record_names, r["rows"])
    if a.compare:
        ref_names, ref_cols = read_twinbench_csv(a.compare)
        c = compare(sys_.record_names, r["rows"], ref_names, ref_cols)
        summary["compare"] = c
        if "error" not in c:
            summary["max_rel"] = max(v["max_rel"] for v in c.values())
            summary["max_abs"] = max(v["max_abs"] for v in c.values())
            summary["bitwise_equal"] = all(v["bitwise_equal"] for v in c.values())
    sys_.cleanup()
    if a.json:
        print(json.dumps(summary, indent=1))
    else:
        for k, v in summary.items():
            if k != "compare":
                print(f"{k:16} {v}")
        for n, v in summary.get("compare", {}).items():
            if isinstance(v, dict):
                print(f"  {n:32} max_abs {v['max_abs']:.3e}  max_rel {v['max_rel']:.3e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
