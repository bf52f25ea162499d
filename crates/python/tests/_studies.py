"""Studies the Python tests build from the bundled one."""

from __future__ import annotations

from pathlib import Path


def two_lap_study(study: Path, system: Path, lap: Path, out: Path) -> Path:
    """`study` over two laps, its system and laps named by absolute paths: `lap` twice, the
    second with weight 2 and its own start speed, a third held out; written to `out`."""
    entries = "".join(
        f'[[measurement]]\nname = "{name}"\nfile = "{lap.as_posix()}"\nweight = {w}\n{extra}\n'
        for name, w, extra in [
            ("one", 1.0, ""),
            ("two", 2.0, '[measurement.parameters]\n"vehicle.v_start" = 52.5\n'),
            ("held", 1.0, "hold_out = true\n"),
        ]
    )
    lines = [
        line
        for line in study.read_text().splitlines()
        if not line.startswith("measurement =") and not line.startswith("system =")
    ]
    out.write_text(f'system = "{system.as_posix()}"\n' + "\n".join(lines) + "\n\n" + entries)
    return out
