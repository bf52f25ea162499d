#!/usr/bin/env python3
"""Reference values for tb-compare's tests, computed with numpy and scipy.

Writes, under crates/compare/tests/fixtures/ (committed, so the Rust tests need no Python):
  reference.json   filter cases (scipy.signal.butter(output="sos"), sosfilt, sosfiltfilt,
                   filtfilt on (b, a), sosfreqz magnitudes) and regression cases
                   (scipy.stats.linregress slope/intercept/R², e of Eq. 16, bias, RMS), plus
                   the expected result of the whole pipeline on the two CSV files below.
  pipeline_meas.csv   a synthetic measurement (50 Hz, with a distance column)
  pipeline_sim.csv    a synthetic simulation (100 Hz, `instance.variable` names, a units row,
                      no distance column: distance is integrated from `vehicle.v`)

Everything is seeded; the pipeline's expectations are computed from the CSV files as
written (re-read), so the text precision of the files does not matter.

Usage: python tools/make_compare_fixture.py   (needs numpy and scipy)
"""

import json
import pathlib

import numpy as np
from scipy import signal, stats
from scipy.integrate import cumulative_trapezoid

OUT = pathlib.Path(__file__).resolve().parent.parent / "crates" / "compare" / "tests" / "fixtures"


def e_of(slope, r2):
    return (1.0 - r2) / 2.0 + abs(slope - 1.0) / 2.0


def figures(meas, sim):
    r = stats.linregress(meas, sim)
    r2 = r.rvalue**2
    return {
        "slope": r.slope,
        "intercept": r.intercept,
        "r_squared": r2,
        "e": e_of(r.slope, r2),
        "bias": float(np.mean(sim - meas) / np.mean(meas)),
        "rms": float(np.sqrt(np.mean((sim - meas) ** 2))),
        "points": int(len(meas)),
    }


def filter_cases(rng):
    fs = 200.0
    n = 600
    t = np.arange(n) / fs
    x = (
        1000.0
        + 3.0 * np.sin(2 * np.pi * 0.5 * t)
        + np.sin(2 * np.pi * 7.0 * t + 0.3)
        + 0.5 * rng.standard_normal(n)
        + 4.0 * (t > 1.5)
    )
    cases = []
    for order, fc in [(2, 2.0), (3, 5.0), (4, 1.0)]:
        sos = signal.butter(order, fc, btype="low", fs=fs, output="sos")
        freqs = [0.5 * fc, fc, 3.0 * fc]
        _, h = signal.sosfreqz(sos, worN=freqs, fs=fs)
        case = {
            "order": order,
            "cutoff_hz": fc,
            "sos": sos.tolist(),
            "freqs_hz": freqs,
            "magnitude": np.abs(h).tolist(),
            "sosfilt": signal.sosfilt(sos, x).tolist(),
            "sosfiltfilt": signal.sosfiltfilt(sos, x).tolist(),
        }
        if order == 2:
            b, a = signal.butter(order, fc, btype="low", fs=fs)
            case["filtfilt_ba"] = signal.filtfilt(b, a, x).tolist()
        cases.append(case)
    return {"sample_rate_hz": fs, "x": x.tolist(), "cases": cases}


def regression_cases(rng):
    n = 500
    s = np.linspace(0.0, 4000.0, n)
    meas = 6000.0 + 900.0 * np.sin(s / 300.0) + 200.0 * np.cos(s / 47.0) + 30.0 * rng.standard_normal(n)
    sims = {
        "scaled": 1.1 * meas - 300.0 + 40.0 * rng.standard_normal(n),
        "noisy": 0.9 * meas + 50.0 + 400.0 * rng.standard_normal(n),
        "offset": meas + 100.0,
    }
    return [
        {"name": k, "meas": meas.tolist(), "sim": v.tolist(), "expected": figures(meas, v)}
        for k, v in sims.items()
    ]


def loads(t, v, rng, lift, noise):
    """Synthetic wheel loads: static + aero (lift ∝ v²) + load transfer from dv/dt."""
    a = np.gradient(v, t)
    aero = 0.5 * lift * 1.5 * 1.18 * v**2
    fl = 2100.0 + 0.2 * aero - 120.0 * a + noise * rng.standard_normal(len(t))
    fr = 2050.0 + 0.2 * aero - 120.0 * a + noise * rng.standard_normal(len(t))
    rl = 2300.0 + 0.3 * aero + 120.0 * a + noise * rng.standard_normal(len(t))
    rr = 2250.0 + 0.3 * aero + 120.0 * a + noise * rng.standard_normal(len(t))
    return fl, fr, rl, rr


def pipeline(rng):
    # Measurement: 50 Hz, 40 s.
    tm = np.arange(0, 40.0 + 1e-9, 0.02)
    vm = 40.0 + 10.0 * np.sin(2 * np.pi * tm / 20.0)
    dm = cumulative_trapezoid(vm, tm, initial=0.0)
    meas_cols = {"time": tm, "distance": dm, "v": vm}
    meas_cols.update(zip(["Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr"], loads(tm, vm, rng, 3.0, 80.0)))
    # Simulation: 100 Hz, slightly longer, a bit slower and with lift too high.
    ts = np.arange(0, 41.0 + 1e-9, 0.01)
    vs = 39.5 + 10.0 * np.sin(2 * np.pi * (ts - 0.2) / 20.0)
    sim_cols = {"time": ts, "vehicle.v": vs}
    sim_cols.update(
        zip(
            ["vehicle.Fz_fl", "vehicle.Fz_fr", "vehicle.Fz_rl", "vehicle.Fz_rr"],
            loads(ts, vs, rng, 3.6, 5.0),
        )
    )
    write_csv(OUT / "pipeline_meas.csv", meas_cols, None)
    write_csv(OUT / "pipeline_sim.csv", sim_cols, ["s", "m/s", "N", "N", "N", "N"])

    # Re-read what was written.
    meas = read_csv(OUT / "pipeline_meas.csv", 1)
    sim = read_csv(OUT / "pipeline_sim.csv", 2)
    cutoff, order, step = 2.0, 2, 1.0

    def prep(cols, prefix, fs):
        sos = signal.butter(order, cutoff, fs=fs, output="sos")
        g = lambda k: cols[prefix + k]
        sig = {
            "Fz_sum": g("Fz_fl") + g("Fz_fr") + g("Fz_rl") + g("Fz_rr"),
            "Fz_front": g("Fz_fl") + g("Fz_fr"),
            "Fz_rear": g("Fz_rl") + g("Fz_rr"),
            "Fz_rl": g("Fz_rl"),
        }
        return {k: signal.sosfiltfilt(sos, v) for k, v in sig.items()}

    t = meas["time"]
    fs_m = (len(t) - 1) / (t[-1] - t[0])
    t = sim["time"]
    fs_s = (len(t) - 1) / (t[-1] - t[0])
    fm = prep(meas, "", fs_m)
    fsim = prep(sim, "vehicle.", fs_s)
    d_m = meas["distance"]
    d_s = cumulative_trapezoid(sim["vehicle.v"], sim["time"], initial=0.0)
    count = int(np.floor((d_m[-1] - d_m[0]) / step + 1e-9)) + 1
    grid = d_m[0] + np.arange(count) * step
    inside = (grid >= d_s[0]) & (grid <= d_s[-1])
    q = grid[inside]
    expected = {}
    for k in fm:
        m_on = np.interp(grid, d_m, fm[k])[inside]
        s_on = np.interp(q, d_s, fsim[k])
        expected[k] = figures(m_on, s_on)
    return {
        "cutoff_hz": cutoff,
        "filter_order": order,
        "distance_step_m": step,
        "grid_points": int(inside.sum()),
        "expected": expected,
    }


def write_csv(path, cols, units):
    names = list(cols)
    data = np.column_stack([cols[k] for k in names])
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        if units:
            f.write(",".join(units) + "\n")
        np.savetxt(f, data, fmt="%.9g", delimiter=",")


def read_csv(path, skip):
    with open(path) as f:
        names = f.readline().strip().split(",")
    data = np.loadtxt(path, delimiter=",", skiprows=skip)
    return {k: data[:, i] for i, k in enumerate(names)}


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(20240605)
    ref = {
        "generator": "tools/make_compare_fixture.py",
        "numpy": np.__version__,
        "scipy": __import__("scipy").__version__,
        "filter": filter_cases(rng),
        "regression": regression_cases(rng),
        "pipeline": pipeline(rng),
    }
    with open(OUT / "reference.json", "w") as f:
        json.dump(ref, f)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
