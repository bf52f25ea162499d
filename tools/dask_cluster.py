#!/usr/bin/env python3
"""A Dask cluster of separate processes started from their command lines, whose workers
share no disk with the coordinator (for tests/test_cluster.py and the distributed
benchmark): a `dask scheduler` and `dask worker` processes, each worker with its own
working folder, HOME (its own store of study files and of unpacked FMUs) and temporary
folder, in a mount namespace where the study's folder is an empty tmpfs (`unshare
--mount`, which needs root or unprivileged user namespaces).
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def project(folder: Path) -> Path:
    """The bundled study, its system, lap and FMUs copied into `folder` with the same
    layout (the study names them by relative paths): the study's folder."""
    for rel in ["studies/spielberg.toml", "systems/rls_v.toml", "data/spielberg_lap.csv"]:
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(ROOT / rel, folder / rel)
    (folder / "target/fmu").mkdir(parents=True)
    for name in ["vehicle", "driver", "dyno", "edu"]:
        shutil.copyfile(ROOT / f"target/fmu/{name}.fmu", folder / f"target/fmu/{name}.fmu")
    return folder / "studies/spielberg.toml"


class Cluster:
    """A scheduler and workers started from their command lines; each worker sees an
    empty folder where `hidden` is."""

    def __init__(self, base: Path, hidden: Path):
        self.base, self.hidden = base, hidden
        self.file = base / "scheduler.json"
        self.workers = {}
        env = self._env(base / "scheduler")
        self.scheduler = subprocess.Popen(
            [BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", self.file],
            cwd=base / "scheduler", env=env,
            stdout=subprocess.DEVNULL, stderr=open(base / "scheduler.log", "w"),
        )
        deadline = time.time() + 60
        while not self.file.exists():
            assert self.scheduler.poll() is None, (base / "scheduler.log").read_text()
            assert time.time() < deadline, "the scheduler did not start"
            time.sleep(0.1)
        from dask.distributed import Client

        self.client = Client(scheduler_file=str(self.file), timeout="60s")

    def _env(self, home: Path) -> dict:
        home.mkdir(parents=True, exist_ok=True)
        (home / "tmp").mkdir(exist_ok=True)
        env = {k: v for k, v in os.environ.items() if not k.startswith("TWINBENCH_")}
        env.update(HOME=str(home), TMPDIR=str(home / "tmp"), PYTHONDONTWRITEBYTECODE="1")
        return env

    def start_worker(self, name: str, preload: Path | None = None) -> subprocess.Popen:
        home = self.base / name
        env = self._env(home)
        dask = [BIN / "dask", "worker", "--scheduler-file", self.file, "--name", name,
                "--nthreads", "1", "--no-nanny", "--no-dashboard",
                "--local-directory", home / "dask"]
        if preload is not None:
            dask += ["--preload", preload]
        # The study's folder is an empty tmpfs in the worker's own mount namespace.
        cmd = ["unshare", "--mount", "--propagation", "private", "--", "sh", "-c",
               'mount -t tmpfs tmpfs "$0" && exec "$@"', self.hidden, *map(str, dask)]
        p = subprocess.Popen(cmd, cwd=home, env=env, stdout=subprocess.DEVNULL,
                             stderr=open(self.base / f"{name}.log", "w"))
        self.workers[name] = p
        return p

    def wait_for(self, n: int):
        self.client.wait_for_workers(n, timeout=120)

    def store(self, name: str) -> Path:
        return self.base / name / ".cache/twinbench/files"

    def close(self):
        try:
            self.client.close()
        finally:
            for p in [*self.workers.values(), self.scheduler]:
                if p.poll() is None:
                    p.send_signal(signal.SIGTERM)
            # One deadline for all: a worker that does not exit on SIGTERM (one refused
            # by the coordinator can wait out its connection timeouts) is killed 20 s after
            # the signal, not 20 s after the one before it was (4 such workers took 80 s).
            deadline = time.monotonic() + 20
            for p in [*self.workers.values(), self.scheduler]:
                try:
                    p.wait(timeout=max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()


