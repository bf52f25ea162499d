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
import os
import signal
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import pytest

import twinbench
from twinbench import _shipping

import _studies

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "tools"))
from dask_cluster import Cluster, project  # noqa: E402

EXE = Path(os.environ.get("TWINBENCH_EXE", ROOT / "target/release/twinbench"))
GENERATIONS = 2


def table1(folder: Path) -> bytes:
    return (folder / "table1.json").read_bytes()


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
        # second, and start a new one, which joins a few seconds later. (The joint
        # refinement's records after the steps have no workers.)
        if record["phase"] != "generation":
            return
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


def test_workers_of_another_version_or_platform_or_without_a_store_are_refused_by_name(cluster, cli_table, tmp_path):
    c, study = cluster
    other = tmp_path / "other_version.py"
    other.write_text("import twinbench._native as n\nn.__version__ = '0.0.0-other'\n")
    alien = tmp_path / "other_platform.py"
    alien.write_text("import twinbench._shipping as s\ns.platform_name = lambda: 'win32-ARM64'\n")
    c.start_worker("good")
    c.start_worker("old", preload=other)
    c.start_worker("alien", preload=alien)
    # A worker whose store is a file, not a folder: it cannot keep the study's files.
    (tmp_path / "full").mkdir()
    c.store("full").parent.mkdir(parents=True)
    c.store("full").write_text("not a folder")
    c.start_worker("full")
    c.wait_for(4)
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
    assert any("is win32-ARM64, the coordinator linux-x86_64" in str(w.message) for w in caught), [
        str(w.message) for w in caught
    ]
    assert any(
        "cannot keep the study's files in its store" in str(w.message) and "TWINBENCH_FILES" in str(w.message)
        for w in caught
    ), [str(w.message) for w in caught]


def test_a_study_naming_its_files_by_absolute_paths_runs_on_workers_without_them(cluster, tmp_path):
    """Two fitted laps and a held-out one, the system and laps named by absolute paths
    (the coordinator's): on a worker they resolve in its mirror of those paths."""
    c, study = cluster
    project_dir = study.parents[1]
    laps = _studies.two_lap_study(
        study, project_dir / "systems/rls_v.toml", project_dir / "data/spielberg_lap.csv",
        project_dir / "studies/two_laps.toml",
    )
    cli = tmp_path / "cli"
    p = subprocess.run([str(EXE), "optimize", str(laps), "--out", str(cli), "--json",
                        "--generations", "1"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    c.start_worker("w1")
    c.start_worker("w2")
    c.wait_for(2)
    seen = c.client.run(lambda p=str(laps): os.path.exists(p))
    assert not any(seen.values()), seen
    out = tmp_path / "out"
    twinbench.Study(laps).optimize(executor=c.client.get_executor(), out=out, generations=1)
    assert table1(out) == table1(cli)


def test_the_files_of_a_coordinator_that_died_are_taken_off_by_the_next_study(cluster, tmp_path):
    """A coordinator killed (SIGKILL) cannot take its study's files off the cluster; the
    next study's coordinator does, and keeps its own and those of one still alive."""
    c, study = cluster
    c.start_worker("w1")
    c.wait_for(1)
    script = (
        "import sys, twinbench\n"
        "from dask.distributed import Client\n"
        f"client = Client(scheduler_file={str(c.file)!r}, timeout='60s')\n"
        f"study = twinbench.Study({str(study)!r})\n"
        "study._shipping(client.get_executor())\n"
        "print(client.id, flush=True)\n"
        "sys.stdin.read()\n"
    )
    # A killed process cannot remove its unpacked FMUs: they go to the test's folder.
    scratch = tmp_path / "coordinators-tmp"
    scratch.mkdir()
    coordinators = [
        subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True,
                         env={**os.environ, "TMPDIR": str(scratch)})
        for _ in range(2)
    ]
    try:
        dead, alive = (p.stdout.readline().strip() for p in coordinators)
        assert dead and alive
        owners = {_shipping._owner(n) for n in c.client.list_datasets()}
        assert {dead, alive} <= owners, owners
        coordinators[0].kill()
        coordinators[0].wait()
        # The scheduler notices the closed connection at once; wait until it has.
        deadline = time.time() + 30
        while dead in c.client.run_on_scheduler(_shipping._client_ids):
            assert time.time() < deadline, "the scheduler still lists the killed coordinator"
            time.sleep(0.1)
        mine = twinbench.Study(study)  # its files stay published while it lives
        mine._shipping(c.client.get_executor())
        owners = {_shipping._owner(n) for n in c.client.list_datasets()}
        assert dead not in owners and {alive, c.client.id} <= owners, owners
    finally:
        for p in coordinators:
            if p.poll() is None:
                p.kill()
            p.wait()
