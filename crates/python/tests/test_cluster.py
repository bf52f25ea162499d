"""A study on a real Dask cluster whose workers share no disk with the coordinator.

A `dask scheduler` and `dask worker` processes are started from their command lines, each
worker with its own working folder, HOME (so its own store of study files and of unpacked
FMUs) and temporary folder, inside a mount namespace in which the study's folder is an
empty tmpfs: the coordinator's paths name nothing there. The study's files travel with the
tasks by content (`twinbench._shipping`), and its Tab. 1 must be the command line's to the
bit: with a worker killed (SIGKILL) and another added mid-study, with a changed byte in a
worker's store, and with a worker of another twinbench version in the cluster (refused by
name, its tasks run by the others).

Needs root (or unprivileged user namespaces) for `unshare --mount`; run by tools/test.sh.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import pytest

import twinbench

ROOT = Path(__file__).resolve().parents[3]
EXE = Path(os.environ.get("TWINBENCH_EXE", ROOT / "target/release/twinbench"))
BIN = Path(sys.executable).parent
GENERATIONS = 2


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


def table1(folder: Path) -> bytes:
    return (folder / "table1.json").read_bytes()


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
            for p in [*self.workers.values(), self.scheduler]:
                try:
                    p.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()


@pytest.fixture(scope="module")
def cli_table(tmp_path_factory):
    """`twinbench optimize` of the study on this machine: the reference."""
    folder = tmp_path_factory.mktemp("cli")
    study = project(folder / "project")
    out = folder / "out"
    p = subprocess.run([str(EXE), "optimize", str(study), "--out", str(out), "--json",
                        "--generations", str(GENERATIONS)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return table1(out)


@pytest.fixture
def cluster(tmp_path):
    study = project(tmp_path / "project")
    c = Cluster(tmp_path, tmp_path / "project")
    try:
        yield c, study
    finally:
        c.close()


def test_workers_without_the_study_folder_give_the_command_lines_table1(cluster, cli_table, tmp_path):
    c, study = cluster
    c.start_worker("w1")
    c.start_worker("w2")
    c.wait_for(2)
    # The workers cannot see the study's folder.
    seen = c.client.run(lambda p=str(study): os.path.exists(p))
    assert seen and not any(seen.values()), seen
    out = tmp_path / "out"
    twinbench.Study(study).optimize(executor=c.client.get_executor(), out=out,
                                    generations=GENERATIONS)
    assert table1(out) == cli_table
    # Each worker keeps the study's files in its own store, by content.
    shas = {hashlib.sha256(p.read_bytes()).hexdigest()
            for p in (tmp_path / "project").rglob("*") if p.is_file()}
    for name in ["w1", "w2"]:
        held = {p.name for p in (c.store(name) / "sha256").rglob("*") if p.is_file()}
        assert shas <= held, (name, shas - held)


def test_a_worker_killed_and_one_added_mid_study_change_nothing(cluster, cli_table, tmp_path):
    c, study = cluster
    victim = c.start_worker("w1")
    c.start_worker("w2")
    c.wait_for(2)
    events, calls, workers = [], [], []

    def progress(record):
        # After the first generation: kill a worker while it runs a candidate of the
        # second, and start a new one, which joins a few seconds later.
        calls.append(record)
        workers.append(record["workers"])
        if len(calls) == 1:
            events.append("killed")
            threading.Timer(0.3, lambda: os.kill(victim.pid, signal.SIGKILL)).start()
            events.append("added")
            c.start_worker("w3")

    out = tmp_path / "out"
    twinbench.Study(study).optimize(executor=c.client.get_executor(), out=out,
                                    generations=GENERATIONS, progress=progress)
    assert events == ["killed", "added"]
    assert victim.poll() == -signal.SIGKILL
    # The progress records say how many workers the study had (w1 gone, w3 come).
    assert workers[0] == 2 and all(n in (1, 2) for n in workers), workers
    assert table1(out) == cli_table
    # The new worker took part: it fetched the study's files into its store.
    assert any((c.store("w3") / "sha256").rglob("*")), "w3 ran no task"


def test_a_changed_byte_in_a_workers_store_is_fetched_again(cluster, cli_table, tmp_path):
    c, study = cluster
    # Worker w1's store already holds the study file, with one byte changed.
    data = bytearray(study.read_bytes())
    sha = hashlib.sha256(data).hexdigest()
    blob = c.store("w1") / "sha256" / sha[:2] / sha
    blob.parent.mkdir(parents=True)
    data[10] ^= 0x20
    blob.write_bytes(bytes(data))
    c.start_worker("w1")
    c.wait_for(1)
    out = tmp_path / "out"
    twinbench.Study(study).optimize(executor=c.client.get_executor(), out=out,
                                    generations=GENERATIONS)
    assert table1(out) == cli_table
    assert hashlib.sha256(blob.read_bytes()).hexdigest() == sha, "the copy was not repaired"
    log = (tmp_path / "w1.log").read_text()
    assert "does not have the content" in log and "fetched again" in log, log[-3000:]


def test_a_worker_of_another_version_is_refused_by_name(cluster, cli_table, tmp_path):
    c, study = cluster
    other = tmp_path / "other_version.py"
    other.write_text("import twinbench._native as n\nn.__version__ = '0.0.0-other'\n")
    c.start_worker("good")
    c.start_worker("old", preload=other)
    c.wait_for(2)
    out = tmp_path / "out"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        twinbench.Study(study).optimize(executor=c.client.get_executor(), out=out,
                                        generations=GENERATIONS)
    assert table1(out) == cli_table
    said = [str(w.message) for w in caught if "runs twinbench 0.0.0-other" in str(w.message)]
    assert said, [str(w.message) for w in caught]
    assert f"the coordinator {twinbench.__version__}" in said[0]
    assert "its tasks go to the other workers" in said[0]
