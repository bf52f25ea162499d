#!/usr/bin/env python3
"""Make the driver's default target speed, v over distance, from the bundled lap.

    python3 tools/make_target_speed.py [data/spielberg_lap.csv] [models/driver/resources/target_speed.csv]

Reads `distance` and `v` of the vehicle measurement (200 Hz, in time), resamples v
onto a 1 m distance grid (linear interpolation), smooths it with a centred moving
average over `WINDOW_M` metres treating the lap as periodic (a flying lap ends where it
starts), and writes `s,v` from 0 up to the lap length, whose last row repeats the first
speed so the target closes on itself. Standard library only; the output is
byte-for-byte reproducible (fixed formatting).
"""

import csv
import math
import sys

SPACING_M = 1.0
# Light smoothing: drops the measurement's sample-to-sample noise, keeps braking
# points sharp (a 9 m window is ~0.2 s at the lap's braking speeds).
WINDOW_M = 9


def main() -> None:
    src = sys.argv[1] if len(sys.argv) > 1 else "data/spielberg_lap.csv"
    dst = sys.argv[2] if len(sys.argv) > 2 else "models/driver/resources/target_speed.csv"
    t, d, v = [], [], []
    with open(src, newline="") as f:
        for row in csv.DictReader(f):
            t.append(float(row["time"]))
            d.append(float(row["distance"]))
            v.append(float(row["v"]))
    for k in range(1, len(d)):
        if not d[k] > d[k - 1]:
            sys.exit(f"{src}: distance not increasing at data row {k + 1}")
    # The lap closes one sample after the last one: extrapolate by its speed.
    lap = d[-1] + v[-1] * (t[-1] - t[-2])
    n = int(math.floor(lap / SPACING_M))
    if lap - n * SPACING_M < 0.5 * SPACING_M:
        n -= 1  # keep the closing row at least half a spacing after the last grid row
    grid = [k * SPACING_M for k in range(n + 1)]

    res = []
    j = 0
    for s in grid:
        while j + 1 < len(d) - 1 and d[j + 1] < s:
            j += 1
        w = (s - d[j]) / (d[j + 1] - d[j])
        w = min(max(w, 0.0), 1.0)
        res.append(v[j] + w * (v[j + 1] - v[j]))

    half = WINDOW_M // 2
    m = len(res)
    smooth = [sum(res[(k + i) % m] for i in range(-half, half + 1)) / (2 * half + 1) for k in range(m)]

    with open(dst, "w", newline="") as f:
        f.write("s,v\n")
        for s, x in zip(grid, smooth):
            f.write(f"{s:.3f},{x:.4f}\n")
        f.write(f"{lap:.3f},{smooth[0]:.4f}\n")
    print(f"{dst}: {m + 1} rows, lap length {lap:.3f} m, v {min(smooth):.2f}..{max(smooth):.2f} m/s")


if __name__ == "__main__":
    main()
