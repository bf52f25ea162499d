#!/usr/bin/env python3
"""Synthetic laps with a known truth, for the calibration of the intervals and the model
check (docs/optimize.md, "How far the intervals can be trusted"):

- ``twin``: the twin's own lap (the bench's RLS/v system with truth parameters) on a
  circuit, and that lap as a logger would give it, with wheel-load noise of a realistic
  autocorrelation (AR(1) in time). Where the twin is the right model.
- ``car``: a lap of a car that is *not* the twin, simulated here independently of
  twinbench's models: its own driver (a quasi-steady lap-time simulation with a driver's
  margins), a sprung chassis (pitch and roll as second-order modes of their own frequency
  and damping), an effective geometry that differs from the nominal one, aerodynamic lift,
  road excitation, white sensor noise. Where the twin is not the right model: its answer is
  compared with the car's *effective* geometry and lift.

Both write ``measurement.csv`` (time, distance, v, a_x, a_y, Fz_fl, Fz_fr, Fz_rl, Fz_rr; a
units row; 200 Hz), ``truth.json`` (the parameters the study should find) and the circuit's
``track.csv`` into the output folder.

Circuits: ``own`` (straights and constant-radius corners, the suite's own), ``spielberg``
(the bundled track), ``random:SEED`` (a closed circuit of random straights and corners).

    tools/synthetic_laps.py twin --circuit own --seed 3 --out DIR
    tools/synthetic_laps.py car --circuit random:7 --seed 7 --out DIR
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TB = Path(os.environ.get("TWINBENCH_EXE", ROOT / "target" / "release" / "twinbench"))
G = 9.81
RATE = 200.0
WHEEL_RADIUS = 0.345
# The twin's nominal car (data/README.md), which the `car` laps share but for the
# effective geometry and lift.
NOMINAL = dict(m=880.0, x_cog=0.615, h_cog=0.345, x_rc=0.5, area=1.5, c_drag=0.767, rho=1.18,
               f_roll=0.02, l=3.10, b_front=1.55, b_rear=1.50)
# Parameters the studies fit.
FITTED = ["vehicle.c_lift_front", "vehicle.c_lift_rear", "vehicle.l", "vehicle.b_front", "vehicle.b_rear"]


# ---- circuits ----


def own_circuit() -> tuple[np.ndarray, np.ndarray, float]:
    """The suite's own circuit (tests/common/synthetic.rs): curvature per 1 m row, a
    feasible target speed, the start speed."""
    segments = [(420, 0.0), (140, 1 / 55), (260, 0.0), (190, -1 / 95), (380, 0.0), (110, 1 / 40),
                (230, 0.0), (170, -1 / 70), (150, 0.0), (200, 1 / 120), (300, 0.0), (90, -1 / 35)]
    kappa = np.concatenate([np.full(n, k) for n, k in segments])
    return kappa, quasi_steady(kappa, a_lat=11.0, a_brake=11.0, a_drive=5.0, v_top=62.0), None


def random_circuit(seed: int) -> tuple[np.ndarray, np.ndarray, None]:
    """A closed circuit of random straights (100-600 m) and corners (radius 30-200 m, 60-250
    m long), about 4 km."""
    rng = np.random.default_rng(seed)
    parts, total = [], 0
    while total < 3800:
        straight = int(rng.uniform(100, 600))
        corner = int(rng.uniform(60, 250))
        radius = rng.uniform(30, 200) * rng.choice([-1, 1])
        parts += [np.zeros(straight), np.full(corner, 1 / radius)]
        total += straight + corner
    kappa = np.concatenate(parts)
    return kappa, quasi_steady(kappa, a_lat=11.0, a_brake=11.0, a_drive=5.0, v_top=62.0), None


def quasi_steady(kappa, a_lat, a_brake, a_drive, v_top, drag=0.0, power=None, mass=880.0):
    """A periodic speed profile on a 1 m grid: corner speeds from a lateral limit, then
    braking and driving limits forwards and backwards, twice round (it is periodic)."""
    n = len(kappa)
    v = np.where(kappa == 0, v_top, np.minimum(np.sqrt(a_lat / np.maximum(np.abs(kappa), 1e-9)), v_top))
    for _ in range(2):
        for i in range(2 * n - 1, -1, -1):
            a, b = i % n, (i + 1) % n
            decel = a_brake + drag * v[b] ** 2 / mass
            v[a] = min(v[a], math.sqrt(v[b] ** 2 + 2 * decel))
        for i in range(1, 2 * n):
            a, b = i % n, (i - 1) % n
            acc = a_drive
            if power is not None:
                acc = min(acc, power / max(v[b], 1.0) / mass - drag * v[b] ** 2 / mass)
            v[a] = min(v[a], math.sqrt(max(v[b] ** 2 + 2 * max(acc, 0.0), 0.0)))
    return v


def spielberg():
    track = np.loadtxt(ROOT / "data" / "spielberg_lap_track.csv", delimiter=",", skiprows=1)
    grid = np.arange(0.0, track[-1, 0], 1.0)
    kappa = np.interp(grid, track[:, 0], track[:, 1])
    return kappa, None, track


def circuit(name: str):
    if name == "own":
        return own_circuit()
    if name == "spielberg":
        return spielberg()
    if name.startswith("random:"):
        return random_circuit(int(name.split(":")[1]))
    raise SystemExit(f"unknown circuit {name!r} (own, spielberg, random:SEED)")


def road(n: int, rms: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Both wheel tracks' heights on a 1 m grid: AR(1) over distance with a 5 m correlation
    length, the two tracks half correlated."""
    rng = np.random.default_rng(seed)
    rho = math.exp(-1 / 5)
    gain = math.sqrt(1 - rho * rho)
    c = l = r = 0.0
    left, right = np.empty(n), np.empty(n)
    for i in range(n):
        c = rho * c + gain * rng.standard_normal()
        l = rho * l + gain * rng.standard_normal()
        r = rho * r + gain * rng.standard_normal()
        left[i] = rms * (c + l) / math.sqrt(2)
        right[i] = rms * (c + r) / math.sqrt(2)
    return left, right


def write_track(path: Path, kappa, left, right):
    with open(path, "w") as f:
        f.write("s,curvature,grade,z_road_left,z_road_right\n")
        for i, k in enumerate(kappa):
            f.write(f"{i},{float(k)!r},0,{float(left[i])!r},{float(right[i])!r}\n")


def write_target(path: Path, v):
    with open(path, "w") as f:
        f.write("s,v\n")
        for i, x in enumerate(v):
            f.write(f"{i},{float(x)!r}\n")
        f.write(f"{len(v)},{float(v[0])!r}\n")


def write_measurement(path: Path, cols: dict):
    names = ["time", "distance", "v", "a_x", "a_y", "Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr"]
    units = ["s", "m", "m/s", "m/s2", "m/s2", "N", "N", "N", "N"]
    data = np.column_stack([cols[n] for n in names])
    with open(path, "w") as f:
        f.write(",".join(names) + "\n" + ",".join(units) + "\n")
        for row in data:
            f.write(",".join(repr(float(x)) for x in row) + "\n")


def ar1(n: int, sigma: float, rho: float, rng) -> np.ndarray:
    e = np.empty(n)
    x = 0.0
    g = math.sqrt(1 - rho * rho)
    for i in range(n):
        x = rho * x + g * rng.standard_normal()
        e[i] = sigma * x
    return e


# The (low, high) ranges the truth parameters are drawn from: (the twin's lap, the car's
# lap). For the car, l, b_front and b_rear are the effective geometry: what the loads'
# transfer behaves as, not the drawing's.
TRUTH_RANGES = {
    "vehicle.c_lift_front": ((0.8, 1.1), (0.75, 1.1)),
    "vehicle.c_lift_rear": ((1.0, 1.4), (0.95, 1.35)),
    "vehicle.l": ((2.8, 3.3), (2.9, 3.5)),
    "vehicle.b_front": ((1.35, 1.6), (1.2, 1.6)),
    "vehicle.b_rear": ((1.3, 1.55), (1.25, 1.55)),
}
TWIN, CAR = 0, 1


def draw_truth(rng, lap):
    """The truth of the `lap` (TWIN or CAR): each parameter drawn uniformly in its range, in
    the table's order, to 4 digits."""
    return {name: round(rng.uniform(*ranges[lap]), 4) for name, ranges in TRUTH_RANGES.items()}


# ---- the twin's own lap ----


def twin_lap(args, out: Path):
    """The bench's RLS/v system with truth parameters on the circuit, run by twinbench; its
    loads with AR(1) noise."""
    rng = np.random.default_rng(args.seed)
    truth = draw_truth(rng, TWIN)
    kappa, target, track = circuit(args.circuit)
    if args.noise_seed is not None:
        # The same truth with another draw of the noise: replicates of one lap.
        rng = np.random.default_rng([args.seed, args.noise_seed])
    params = {}
    if track is None:
        left, right = road(len(kappa), args.road_rms, args.seed + 1)
        write_track(out / "track.csv", kappa, left, right)
        write_target(out / "truth_target.csv", target)
        params["vehicle.track_file"] = str(out / "track.csv")
        params["driver.target_speed_file"] = str(out / "truth_target.csv")
        v0 = float(target[0])
    else:
        (out / "track.csv").write_bytes((ROOT / "data" / "spielberg_lap_track.csv").read_bytes())
        v0 = 52.43
    params.update({"vehicle.v_start": v0, "dyno_rl.omega_start": v0 / WHEEL_RADIUS,
                   "dyno_rr.omega_start": v0 / WHEEL_RADIUS, "edu.omega_wheel_start": v0 / WHEEL_RADIUS})
    params.update(truth)
    system = bench_system(params, out)
    lap = run(system, out / "truth_run.csv")
    n = len(lap["time"])
    cols = {
        "time": lap["time"], "distance": lap["vehicle.distance"], "v": lap["vehicle.v"],
        "a_x": lap["vehicle.a_x"], "a_y": lap["vehicle.a_y"],
    }
    for w in ["fl", "fr", "rl", "rr"]:
        cols[f"Fz_{w}"] = lap[f"vehicle.Fz_{w}"] + ar1(n, args.sigma, args.rho, rng)
    write_measurement(out / "measurement.csv", cols)
    (out / "truth.json").write_text(json.dumps({"kind": "twin", "circuit": args.circuit, "seed": args.seed,
                                                "truth": truth, "noise": {"sigma": args.sigma, "rho": args.rho}},
                                               indent=1))


def bench_system(params: dict, out: Path) -> Path:
    """systems/rls_v.toml with `params` set over its own, recording every 5 ms."""
    import re

    text = (ROOT / "systems" / "rls_v.toml").read_text()
    text = text.replace('"../target/fmu/', f'"{ROOT}/target/fmu/')
    head, rest = text.split("[parameters]\n", 1)
    body, tail = rest.split("\n# The vehicle's track and", 1)
    kept = [line for line in body.splitlines()
            if not any(line.startswith(f'"{k}"') for k in params)]
    lines = kept + [f'"{k}" = {json.dumps(v)}' for k, v in params.items()]
    text = head + "[parameters]\n" + "\n".join(lines) + "\n\n# The vehicle's track and" + tail
    text = re.sub(r"decimation = \d+", "decimation = 5", text)
    path = out / "truth.toml"
    path.write_text(text)
    return path


def run(system: Path, csv: Path) -> dict:
    p = subprocess.run([str(TB), "run", str(system), "--out", str(csv)], capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"the truth lap failed:\n{p.stderr}")
    with open(csv) as f:
        names = f.readline().strip().split(",")
        f.readline()
        d = np.loadtxt(f, delimiter=",")
    return {n: d[:, i] for i, n in enumerate(names)}


# ---- a car that is not the twin ----


def second_order(x: np.ndarray, dt: float, f: float, zeta: float) -> np.ndarray:
    """x through a second-order mode (unit gain), exact for x held over each sample."""
    w = 2 * math.pi * f
    a = np.array([[0.0, 1.0], [-w * w, -2 * zeta * w]])
    b = np.array([0.0, w * w])
    # Zero-order hold: the matrix exponential of [[A, B], [0, 0]].
    m = np.zeros((3, 3))
    m[:2, :2] = a * dt
    m[:2, 2] = b * dt
    from scipy.linalg import expm

    e = expm(m)
    ad, bd = e[:2, :2], e[:2, 2]
    y = np.empty_like(x)
    s = np.array([x[0], 0.0])
    for i, u in enumerate(x):
        y[i] = s[0]
        s = ad @ s + bd * u
    return y


def car_lap(args, out: Path):
    rng = np.random.default_rng(args.seed)
    p = dict(NOMINAL)
    truth = draw_truth(rng, CAR)
    modes = dict(pitch_frequency=round(rng.uniform(1.8, 3.0), 3), pitch_damping=round(rng.uniform(0.35, 0.7), 3),
                 roll_frequency=round(rng.uniform(1.5, 2.6), 3), roll_damping=round(rng.uniform(0.35, 0.7), 3))
    kappa, _, track = circuit(args.circuit)
    n = len(kappa)
    if track is None:
        left, right = road(n, args.road_rms, args.seed + 1)
    else:
        s_t = track[:, 0]
        left = np.interp(np.arange(n), s_t, track[:, 3])
        right = np.interp(np.arange(n), s_t, track[:, 4])
    write_track(out / "track.csv", kappa, left, right)
    # Its own driver: a quasi-steady lap at this car's limits, with a margin of its own in
    # each corner (0-4 % below the limit speed) and a braking effort of 85-100 %.
    margin = np.ones(n)
    corner = np.abs(kappa) > 0
    edges = np.flatnonzero(np.diff(corner.astype(int)) == 1) + 1
    for e in edges:
        m = 1 - rng.uniform(0.0, 0.04)
        end = e
        while end < n and corner[end]:
            end += 1
        margin[e:end] = m
    drag = 0.5 * p["rho"] * p["c_drag"] * p["area"]
    a_lat = rng.uniform(10.0, 12.5)
    v_s = quasi_steady(kappa, a_lat=a_lat, a_brake=rng.uniform(0.85, 1.0) * 14.0, a_drive=6.5,
                       v_top=80.0, drag=drag, power=180e3, mass=p["m"])
    v_s = np.minimum(v_s, np.where(corner, np.sqrt(a_lat / np.maximum(np.abs(kappa), 1e-9)) * margin, 1e9))
    # Smoothed as a driver's inputs are (no instant jumps in acceleration): 9 m.
    v_s = np.convolve(np.concatenate([v_s[-4:], v_s, v_s[:4]]), np.ones(9) / 9, mode="valid")
    # Time along the lap, then a 200 Hz log.
    dt_s = 1.0 / np.maximum(v_s, 1.0)
    t_s = np.concatenate([[0.0], np.cumsum(0.5 * (dt_s[1:] + dt_s[:-1]))])
    t = np.arange(0.0, t_s[-1], 1 / RATE)
    s = np.interp(t, t_s, np.arange(n))
    v = np.interp(s, np.arange(n), v_s)
    a_x = np.gradient(v, 1 / RATE)
    k_t = np.interp(s, np.arange(n), kappa)
    a_y = v * v * k_t
    # The sprung chassis.
    ax_c = second_order(a_x, 1 / RATE, modes["pitch_frequency"], modes["pitch_damping"])
    ay_c = second_order(a_y, 1 / RATE, modes["roll_frequency"], modes["roll_damping"])
    q = p["area"] * p["rho"] * v * v
    lf, lr = 0.25 * truth["vehicle.c_lift_front"] * q, 0.25 * truth["vehicle.c_lift_rear"] * q
    long = ax_c * p["h_cog"] / truth["vehicle.l"]
    rear = 0.5 * (p["x_cog"] * G + long)
    front = 0.5 * ((1 - p["x_cog"]) * G - long)
    lat_r = (1 - p["x_rc"]) * ay_c * p["h_cog"] / truth["vehicle.b_rear"]
    lat_f = p["x_rc"] * ay_c * p["h_cog"] / truth["vehicle.b_front"]
    k_road = 150000.0
    zl_f, zr_f = np.interp(s, np.arange(n), left), np.interp(s, np.arange(n), right)
    zl_r, zr_r = np.interp(s - 3.10, np.arange(n), left, period=n), np.interp(s - 3.10, np.arange(n), right, period=n)
    m = p["m"]
    loads = {
        "Fz_fl": m * (front - lat_f) + lf + k_road * zl_f,
        "Fz_fr": m * (front + lat_f) + lf + k_road * zr_f,
        "Fz_rl": m * (rear - lat_r) + lr + k_road * zl_r,
        "Fz_rr": m * (rear + lat_r) + lr + k_road * zr_r,
    }
    cols = {"time": t, "distance": s, "v": v + rng.normal(0, 0.02, len(t)),
            "a_x": a_x + rng.normal(0, 0.05, len(t)), "a_y": a_y + rng.normal(0, 0.05, len(t))}
    for k, x in loads.items():
        cols[k] = x + rng.normal(0, args.white, len(t))
    write_measurement(out / "measurement.csv", cols)
    (out / "truth.json").write_text(json.dumps({"kind": "car", "circuit": args.circuit, "seed": args.seed,
                                                "truth": truth, "modes": modes, "a_lat": a_lat}, indent=1))


def main(argv=None):
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("kind", choices=["twin", "car"])
    a.add_argument("--circuit", default="own")
    a.add_argument("--seed", type=int, default=1)
    a.add_argument("--out", type=Path, required=True)
    a.add_argument("--noise-seed", type=int, default=None,
                   help="twin: draw the noise from this seed (the truth stays the --seed's)")
    a.add_argument("--sigma", type=float, default=150.0, help="twin: AR(1) load noise [N]")
    a.add_argument("--rho", type=float, default=0.995, help="twin: AR(1) correlation per 5 ms")
    a.add_argument("--white", type=float, default=25.0, help="car: white load noise [N]")
    a.add_argument("--road-rms", type=float, default=0.002, help="road height rms [m]")
    args = a.parse_args(argv)
    args.out = args.out.resolve()
    args.out.mkdir(parents=True, exist_ok=True)
    (twin_lap if args.kind == "twin" else car_lap)(args, args.out)


if __name__ == "__main__":
    sys.exit(main())
