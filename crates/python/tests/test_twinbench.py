"""The Python package against the command line: the same numbers, the same messages, the
same Tab. 1 wherever the candidates run (threads, a process pool, a Dask LocalCluster,
one of whose workers is killed mid-study), and resume after an interrupted distributed
study. Run by tools/test.sh after the wheel is installed into target/venv.

Needs TWINBENCH_EXE (the command line built from the same sources) and the packed FMUs.
"""

from __future__ import annotations

import concurrent.futures
import json
import math
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import twinbench

import _studies

ROOT = Path(__file__).resolve().parents[3]
EXE = Path(os.environ.get("TWINBENCH_EXE", ROOT / "target/release/twinbench"))
STUDY = ROOT / "studies/spielberg.toml"
SYSTEM = ROOT / "systems/rls_v.toml"


def cli(*args, check=True):
    p = subprocess.run([str(EXE), *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    if check and p.returncode != 0:
        raise AssertionError(f"twinbench {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p


@pytest.fixture(scope="session", autouse=True)
def worker_temporary_files(tmp_path_factory):
    """Unpacked FMUs of worker processes go below pytest's folder: a worker killed on
    purpose cannot clean up after itself, and the suite's TMPDIR must stay empty."""
    import tempfile

    import dask

    folder = tmp_path_factory.getbasetemp() / "tmp"
    folder.mkdir(exist_ok=True)
    old = os.environ.get("TMPDIR")
    os.environ["TMPDIR"] = str(folder)
    # Python caches its temporary folder on first use (Dask's scratch space goes there).
    old_tempdir, tempfile.tempdir = tempfile.tempdir, str(folder)
    with dask.config.set({"temporary-directory": str(folder)}):
        yield
    tempfile.tempdir = old_tempdir
    if old is None:
        del os.environ["TMPDIR"]
    else:
        os.environ["TMPDIR"] = old


@pytest.fixture(scope="session", autouse=True)
def packed_fmus():
    assert EXE.exists(), f"{EXE}: build twinbench first (cargo build --release)"
    if not (ROOT / "target/fmu/vehicle.fmu").exists():
        cli("pack", "-o", ROOT / "target/fmu")


@pytest.fixture(scope="session")
def cli_study(tmp_path_factory):
    """`twinbench optimize` of the Spielberg study: the reference every other run must equal."""
    out = tmp_path_factory.mktemp("cli_study")
    cli("optimize", STUDY, "--out", out, "--json", "--threads", "2")
    return out


def read_csv(path: Path):
    with open(path) as f:
        names = f.readline().rstrip("\n").split(",")
        f.readline()  # units
        rows = [line.rstrip("\n").split(",") for line in f]
    return {n: np.array([float(r[k]) for r in rows]) for k, n in enumerate(names)}


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


def run_both_ways(target, out, name, value):
    """`twinbench run TARGET --out OUT --set NAME=VALUE` and `twinbench.run` with the same
    parameter give the same signals, bit for bit: the module's result and the command's
    columns."""
    cli("run", target, "--out", out, "--set", f"{name}={value}")
    expected = read_csv(out)
    result = twinbench.run(target, parameters={name: value})
    assert list(result.signals) == list(expected)
    for signal, column in expected.items():
        assert same_bits(result.signals[signal], column), signal
    return result, expected


# ---- run and compare ----


def test_run_gives_the_bits_of_run_out(tmp_path):
    result, expected = run_both_ways(SYSTEM, tmp_path / "lap.csv", "vehicle.c_lift_front", 0.9)
    assert result.units["vehicle.v"] == "m/s"
    # A lap of the Spielberg track: about 98 s (the bench's lap time, not a figure we fix).
    assert 95.0 < result.summary["lap_time"] < 101.0
    assert result.summary["stopped_by"] == "vehicle.lap >= 1"
    frame = result.to_pandas()
    assert frame.index.name == "time" and len(frame) == len(expected["time"])


def test_one_fmu_runs_on_its_own_as_the_command_line_runs_it(tmp_path):
    fmu = ROOT / "target" / "fmu" / "dyno.fmu"
    run_both_ways(fmu, tmp_path / "dyno.csv", "time_constant", 0.02)


def test_stop_override_and_condition():
    r = twinbench.run(SYSTEM, stop=2.0)
    assert r.signals["time"][-1] == pytest.approx(2.0, abs=1e-12)
    r = twinbench.run(SYSTEM, stop="vehicle.distance >= 100")
    # Stops at the first communication point where it holds; the recording (100 Hz) ends
    # within one recording interval before it (v ≈ 52 m/s: 0.53 m per 10 ms).
    assert r.summary["stopped_by"] == "vehicle.distance >= 100"
    assert 1.85 < r.summary["simulated_time"] < 1.95
    assert 99.4 < r.signals["vehicle.distance"][-1] < 100.06


def test_an_observer_watches_the_run_and_can_end_it():
    """`twinbench.run(..., observer=f, every=1.0)`: f sees the start, every simulated
    second and the end, with the values the recording has at those times (bit for bit);
    its reason ends the run; its exception is raised as itself."""
    seen = []

    def watch(t, values):
        seen.append((t, values["vehicle.v"], values["vehicle.distance"]))
        return "enough of this lap" if t >= 5.0 else None

    r = twinbench.run(SYSTEM, observer=watch, every=1.0)
    assert r.summary["stopped_by"] == "enough of this lap"
    assert r.signals["time"][-1] == 5.0
    # Calls at 0, 1, ..., 5 s (1000 steps of 1 ms each); the end was the last call.
    assert [s[0] for s in seen] == [float(k) for k in range(6)]
    for t, v, distance in seen:
        row = int(np.searchsorted(r.signals["time"], t))
        assert r.signals["time"][row] == t
        assert same_bits(np.array([v, distance]),
                         np.array([r.signals["vehicle.v"][row], r.signals["vehicle.distance"][row]]))
    # Going on by default: the whole lap with the observer equals the lap without it.
    calls = []
    watched = twinbench.run(SYSTEM, stop=3.0, observer=lambda t, v: calls.append(t))
    plain = twinbench.run(SYSTEM, stop=3.0)
    for name, column in plain.signals.items():
        assert same_bits(watched.signals[name], column), name
    # Default: at each recorded row (here every 5 ms), the end told once.
    assert calls == list(watched.signals["time"])

    class Broken(Exception):
        pass

    def broken(t, values):
        if t > 0.5:
            raise Broken("a plot window went away")

    with pytest.raises(Broken, match="a plot window went away"):
        twinbench.run(SYSTEM, observer=broken)
    with pytest.raises(TypeError, match="expected None or True"):
        twinbench.run(SYSTEM, observer=lambda t, v: 42)
    with pytest.raises(twinbench.TwinbenchError, match="every = 0: expected a positive time"):
        twinbench.run(SYSTEM, observer=lambda t, v: None, every=0.0)


def test_ctrl_c_during_a_run_raises_keyboard_interrupt_where_the_run_was():
    """SIGINT while a long run goes on (here 3000 s of simulated time, seconds of wall
    time) stops it after the step under way: KeyboardInterrupt, saying where."""

    def start_the_clock(t, values):
        # At the run's start, inside the run: the signal cannot come before it.
        threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT)).start()

    # Python's own handler, also where SIGINT came ignored (a job started in the background).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt) as caught:
            twinbench.run(SYSTEM, stop=3000.0, observer=start_the_clock, every=1e4)
    finally:
        signal.signal(signal.SIGINT, previous)
    if sys.version_info < (3, 11):
        return  # no exception notes before Python 3.11
    notes = getattr(caught.value, "__notes__", [])
    assert any(n.startswith("twinbench.run: stopped after the step to t = ") for n in notes), notes
    t = float(notes[-1].split("t = ")[1].split(" s")[0])
    assert 0.0 < t < 3000.0


def test_a_bad_system_raises_the_command_lines_message(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((SYSTEM.read_text()).replace('"vehicle.v -> driver.v"', '"vehicle.vv -> driver.v"'))
    # The FMU paths are relative to the system file: keep it beside the original.
    bad_here = SYSTEM.parent / f"bad-{os.getpid()}.toml"
    bad_here.write_text(bad.read_text())
    try:
        p = cli("run", bad_here, check=False)
        assert p.returncode != 0
        message = p.stderr.strip().splitlines()[-1]
        assert message.startswith("error: ")
        with pytest.raises(twinbench.TwinbenchError) as e:
            twinbench.run(bad_here)
        assert str(e.value) == message[len("error: "):]
        assert "vehicle.vv" in str(e.value)
    finally:
        bad_here.unlink()
    with pytest.raises(twinbench.TwinbenchError, match="cannot read"):
        twinbench.run(tmp_path / "missing.toml")
    with pytest.raises(twinbench.TwinbenchError, match="c_lift_frnt"):
        twinbench.run(SYSTEM, parameters={"vehicle.c_lift_frnt": 1.0})


def test_compare_gives_the_command_lines_metrics(tmp_path):
    out = tmp_path / "lap.csv"
    cli("run", SYSTEM, "--out", out)
    p = cli("compare", out, ROOT / "data/spielberg_lap.csv", "--signals", "Fz_sum,Fz_rl", "--json")
    expected = {s["signal"]: s for s in json.loads(p.stdout)["comparison"]["signals"]}
    c = twinbench.compare(twinbench.run(SYSTEM), ROOT / "data/spielberg_lap.csv", signals=["Fz_sum", "Fz_rl"])
    for name in ["Fz_sum", "Fz_rl"]:
        assert c[name].e == expected[name]["e"]
        assert c[name].m == expected[name]["slope"]
        assert c[name].r_squared == expected[name]["r_squared"]
        assert c[name].bias == expected[name]["bias"]
    with pytest.raises(twinbench.TwinbenchError, match="Fz_nope"):
        twinbench.compare(twinbench.run(SYSTEM, stop=5.0), ROOT / "data/spielberg_lap.csv", signals="Fz_nope", min_coverage=0.0)
    # A misspelt signal is named with the closest ones (the derived Fz_sum among them).
    with pytest.raises(twinbench.TwinbenchError, match="no signal `Fz_summ`; closest: Fz_sum"):
        twinbench.compare(twinbench.run(SYSTEM, stop=5.0), ROOT / "data/spielberg_lap.csv", signals=["Fz_summ"], min_coverage=0.0)


def test_help_reads_well():
    doc = twinbench.run.__doc__
    assert "instance.variable" in doc and "Raises" in doc
    assert "executor" in twinbench.Study.optimize.__doc__


# ---- studies ----


def table1(folder: Path) -> bytes:
    return (folder / "table1.json").read_bytes()


def local_cluster(tmp_path, n=2):
    from dask.distributed import Client, LocalCluster

    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        local_directory=str(tmp_path / "dask"),
    )
    return cluster, Client(cluster)


def test_a_dask_study_gives_the_command_lines_table1(cli_study, tmp_path):
    cluster, client = local_cluster(tmp_path)
    try:
        out = tmp_path / "dask"
        result = twinbench.Study(STUDY).optimize(executor=client.get_executor(), out=out)
        # Every worker process loaded the study once and kept it.
        loaded = client.run(lambda: __import__("twinbench._worker")._worker.loaded())
        assert loaded == {w: 1 for w in client.scheduler_info()["workers"]}
    finally:
        client.close()
        cluster.close()
    assert table1(out) == table1(cli_study)
    expected = json.loads((cli_study / "result.json").read_text())
    for a, b in zip(result["steps"], expected["steps"], strict=True):
        assert a["after_exact"] == b["after_exact"] and a["history"] == b["history"]
        # The same step results wherever the candidates ran.
        assert a["e"] == b["e"]
    # Each fitted parameter with its interval, as the command line's JSON has it.
    params = result["parameters"]
    assert set(params) == {p["name"] for s in expected["steps"] for p in s["parameters"]}
    assert result["joint_intervals"] == expected["joint_intervals"]
    assert result["joint"] == expected["joint"]
    # The study's answer: every parameter refined together, with its joint interval.
    for p in expected["joint"]["parameters"]:
        mine = params[p["name"]]
        assert mine["value"] == p["after"] and mine["interval"] == p["interval"]
        assert mine["interval_method"] == "gauss-newton-hac"
        lo, hi = mine["interval"]
        assert lo is None or lo < mine["value"]
        assert hi is None or mine["value"] < hi
        # The interval with the model's share holds the scatter interval.
        assert mine["std_error"] == p["std_error"] and mine["std_error"] > 0
        wlo, whi = mine["interval_with_model"]
        assert (wlo is None or lo is None or wlo <= lo) and (whi is None or hi is None or whi >= hi)
    assert params["vehicle.l"]["unit"] == "m"
    # The model check, in words an engineer reads.
    check = result["model_check"]
    assert check == expected["joint"]["model_check"]
    assert isinstance(check["discrepancy"], bool) and 0.0 <= check["p_value"] <= 1.0
    assert "the twin" in check["detail"]


def two_lap_study(folder: Path) -> Path:
    """The bundled study over two laps (`_studies.two_lap_study`) in `folder`."""
    return _studies.two_lap_study(
        STUDY, ROOT / "systems/rls_v.toml", ROOT / "data/spielberg_lap.csv", folder / "two_laps.toml"
    )


def test_a_study_of_two_laps_on_dask_equals_the_command_line(tmp_path):
    study = two_lap_study(tmp_path)
    cli("optimize", study, "--out", tmp_path / "cli", "--json", "--generations", "2")
    cluster, client = local_cluster(tmp_path)
    try:
        result = twinbench.Study(study).optimize(
            executor=client.get_executor(), out=tmp_path / "dask", generations=2
        )
    finally:
        client.close()
        cluster.close()
    assert table1(tmp_path / "dask") == table1(tmp_path / "cli")
    expected = json.loads((tmp_path / "cli" / "result.json").read_text())
    assert result["joint"] == expected["joint"]
    # A row per lap and signal, and the held-out lap's.
    laps = {e["lap"] for e in result["joint"]["e"]}
    assert laps == {"one", "two"}
    assert {e["lap"] for e in result["hold_out"]} == {"held"}
    md = (tmp_path / "dask" / "table1.md").read_text()
    assert "| Fz_sum (two) |" in md and "| held out |" in md


def test_the_joint_fit_and_its_profiles_run_on_dask_as_on_the_command_line(tmp_path):
    # The lift step alone, with profiles: the refinement's and the profiles' laps are
    # tasks on the workers, and the answer, the intervals and every profile point are the
    # command line's to the bit.
    text = STUDY.read_text()
    text = text[: text.index("# Step 2")].replace("\n[compare]", "\nprofiles = true\n\n[compare]", 1)
    text = text.replace('"../', f'"{ROOT.as_posix()}/')
    study = tmp_path / "lift.toml"
    study.write_text(text)
    cli("optimize", study, "--out", tmp_path / "cli", "--json", "--generations", "3")
    cluster, client = local_cluster(tmp_path)
    try:
        result = twinbench.Study(study).optimize(
            executor=client.get_executor(), out=tmp_path / "dask", generations=3
        )
        served = client.run(lambda: __import__("twinbench._worker")._worker.points())
    finally:
        client.close()
        cluster.close()
    expected = json.loads((tmp_path / "cli" / "result.json").read_text())
    profiles = result["profiles"]
    # Every lap of the refinement and the profiles ran on a worker (none here), on both.
    assert sum(served.values()) == expected["joint"]["refinement"]["laps"] + profiles["laps"]
    assert all(n > 0 for n in served.values()), served
    assert result["joint"] == expected["joint"]
    for mine, theirs in zip(profiles["parameters"], expected["profiles"]["parameters"], strict=True):
        assert mine == theirs
    assert table1(tmp_path / "dask") == table1(tmp_path / "cli")


def test_the_bootstrap_runs_on_dask_as_on_the_command_line(tmp_path):
    # The lift step alone with `--bootstrap 4`: the refits' laps are tasks on the workers,
    # and the bootstrap (its draws seeded by the study) is the command line's to the bit.
    text = STUDY.read_text()
    text = text[: text.index("# Step 2")].replace('"../', f'"{ROOT.as_posix()}/')
    study = tmp_path / "lift.toml"
    study.write_text(text)
    cli("optimize", study, "--out", tmp_path / "cli", "--json", "--generations", "3", "--bootstrap", "4")
    cluster, client = local_cluster(tmp_path)
    try:
        result = twinbench.Study(study).optimize(
            executor=client.get_executor(), out=tmp_path / "dask", generations=3, bootstrap=4
        )
        served = client.run(lambda: __import__("twinbench._worker")._worker.points())
    finally:
        client.close()
        cluster.close()
    expected = json.loads((tmp_path / "cli" / "result.json").read_text())
    boot = result["joint"]["bootstrap"]
    assert boot == expected["joint"]["bootstrap"]
    assert boot["replicates"] == 4 and boot["completed"] == 4 and boot["block"] >= 10
    for p in boot["parameters"]:
        lo, hi = p["interval"]
        assert p["std_error"] > 0 and p["ratio"] > 0 and lo < hi
    assert sum(served.values()) == expected["joint"]["refinement"]["laps"] + boot["laps"]
    assert "Bootstrap (4 of 4 refits" in (tmp_path / "dask" / "table1.md").read_text()


def test_a_worker_killed_mid_study_changes_nothing(cli_study, tmp_path):
    cluster, client = local_cluster(tmp_path)
    killed = []

    def kill_one():
        pids = client.run(os.getpid)
        victim = sorted(pids.values())[0]
        os.kill(victim, signal.SIGKILL)
        killed.append(victim)

    def progress(record):
        # In the second generation's candidates: kill a worker while it runs one.
        if record["phase"] == "generation" and record["generation"] == 1 and not killed:
            threading.Timer(0.4, kill_one).start()

    try:
        out = tmp_path / "killed"
        twinbench.Study(STUDY).optimize(executor=client.get_executor(), out=out, progress=progress)
    finally:
        client.close()
        cluster.close()
    assert killed, "no worker was killed"
    assert table1(out) == table1(cli_study)


class FailingExecutor(concurrent.futures.Executor):
    """A process pool that is lost after `tasks` tasks (a cluster gone mid-study)."""

    def __init__(self, pool, tasks):
        self.pool, self.left = pool, tasks

    def submit(self, fn, *args, **kwargs):
        self.left -= 1
        if self.left < 0:
            raise RuntimeError("the cluster went away")
        return self.pool.submit(fn, *args, **kwargs)


def test_an_interrupted_distributed_study_resumes_to_the_same_table1(cli_study, tmp_path):
    out = tmp_path / "resumed"
    study = twinbench.Study(STUDY)
    with concurrent.futures.ProcessPoolExecutor(2) as pool:
        with pytest.raises(RuntimeError, match="the cluster went away"):
            study.optimize(executor=FailingExecutor(pool, 45), out=out)
        checkpoint = json.loads((out / "spielberg.checkpoint.json").read_text())
        assert checkpoint["checkpoint"]["current"]["run"]["history"], "a generation was checkpointed"
        assert not (out / "table1.json").exists()
        study.optimize(executor=pool, out=out, resume=True)
    assert table1(out) == table1(cli_study)


def test_ask_tell_with_an_optimiser_of_ones_own(cli_study):
    study = twinbench.Study(STUDY)
    step = study.steps[0]
    reference = json.loads((cli_study / "result.json").read_text())["steps"][0]
    start = [p["before"] for p in reference["parameters"]]
    costs = study.evaluate(0, [start], threads=1)
    # The same candidate, the same cost as the study's own start point, to the bit.
    assert costs[0] == reference["cost_before"]
    opt = twinbench.Optimizer("cmaes", step.bounds, seed=7, start=start)
    told = []
    for _ in range(2):
        xs = opt.ask()
        assert all(lo <= v <= hi for x in xs for v, (lo, hi) in zip(x, step.bounds))
        c = study.evaluate(0, xs)
        opt.tell(c)
        told += c
    best_x, best_cost = opt.best()
    assert opt.generation == 2
    assert best_cost == min(told)
    assert all(lo <= v <= hi for v, (lo, hi) in zip(best_x, step.bounds))
    with pytest.raises(twinbench.TwinbenchError, match="costs for the"):
        opt.ask()
        opt.tell([1.0])
    with pytest.raises(twinbench.TwinbenchError, match="values for the"):
        study.evaluate(0, [[1.0]])


def test_evaluate_on_dask_sends_the_study_files_once_per_cluster(tmp_path):
    """An ask/tell loop of one's own on a Dask cluster: every generation's costs equal the
    threads', and the study's files are published to the cluster once (by content), not
    per call; they leave the cluster with the Study."""
    import gc

    study = twinbench.Study(STUDY)
    step = study.steps[0]
    cands = [[lo + (k + 1) * (hi - lo) / 5 for lo, hi in step.bounds] for k in range(3)]
    here = study.evaluate(0, cands, threads=1)
    cluster, client = local_cluster(tmp_path)
    try:
        ex = client.get_executor()
        assert study.evaluate(0, cands, executor=ex) == here
        published = set(client.list_datasets())
        files = {sha for _, sha in study._loaded().contents()}
        assert {n.rsplit("-", 1)[1] for n in published} == files
        assert study.evaluate(0, cands[::-1], executor=ex) == here[::-1]
        assert set(client.list_datasets()) == published, "published again"
        del study
        gc.collect()
        assert client.list_datasets() == ()
    finally:
        client.close()
        cluster.close()


def test_a_worker_refuses_a_shipment_that_would_climb_out_of_its_store(tmp_path, monkeypatch):
    from twinbench import _shipping

    monkeypatch.setenv("TWINBENCH_FILES", str(tmp_path / "store"))
    sha = "0" * 64
    for path, digest in [("/a/../../etc/passwd", sha), ("relative/x.toml", sha), ("/a/x.toml", "../" + "0" * 61)]:
        shipment = (_shipping._TAG, _shipping._LAYOUT, "/a/x.toml", ((path, digest, "name"),),
                    twinbench.__version__, _shipping.platform_name())
        with pytest.raises(twinbench.TwinbenchError, match="expected an absolute path without '..' and a SHA-256"):
            _shipping.study_path(shipment)
    assert not (tmp_path / "store").exists()


def _shipment(files, coordinator="/proj/study.toml"):
    from twinbench import _shipping

    return (_shipping._TAG, _shipping._LAYOUT, coordinator, tuple(files), twinbench.__version__,
            _shipping.platform_name())


def test_a_path_shipped_with_two_digests_is_refused(tmp_path, monkeypatch):
    # Red team 5: one path named twice with two digests was resolved silently (the last won).
    from twinbench import _shipping

    monkeypatch.setenv("TWINBENCH_FILES", str(tmp_path / "store"))
    shipment = _shipment([("/proj/study.toml", "a" * 64, "k1"), ("/proj/study.toml", "b" * 64, "k2")])
    with pytest.raises(twinbench.TwinbenchError, match="named the file '/proj/study.toml' twice, with the digests a+ and b+"):
        _shipping.study_path(shipment)
    assert not (tmp_path / "store").exists()


def test_a_link_planted_in_a_workers_mirror_is_refused_not_followed(tmp_path, monkeypatch):
    # Red team 5: a symbolic link planted inside a worker's mirror (by someone who can write
    # its store) was followed by mkdir and os.replace, out of the store.
    import hashlib

    from twinbench import _shipping

    store = tmp_path / "store"
    monkeypatch.setenv("TWINBENCH_FILES", str(store))
    _shipping.forget()
    data = b"name = 'x'\n"
    sha = hashlib.sha256(data).hexdigest()
    # The blob is in the store already (no cluster needed to fetch it), the coordinator's
    # path is not on this machine: the mirror is built.
    blob = store / "sha256" / sha[:2] / sha
    blob.parent.mkdir(parents=True)
    blob.write_bytes(data)
    files = [("/proj/study.toml", sha, "k")]
    ident = hashlib.sha256(repr(sorted((p, s) for p, s, _ in files)).encode()).hexdigest()[:32]
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (store / "mirrors" / ident).mkdir(parents=True)
    (store / "mirrors" / ident / "proj").symlink_to(elsewhere)
    with pytest.raises(twinbench.TwinbenchError, match="symbolic link or not a folder: something was planted"):
        _shipping.study_path(_shipment(files))
    assert list(elsewhere.iterdir()) == []
    # Removed, the mirror is built as it should be.
    (store / "mirrors" / ident / "proj").unlink()
    local = _shipping.study_path(_shipment(files))
    assert Path(local).read_bytes() == data
    assert Path(local).parent.resolve().is_relative_to(store.resolve())
    _shipping.forget()


# ---- the first hour ----


def test_a_lap_of_ones_own_runs_by_a_relative_name(tmp_path, monkeypatch):
    """`twinbench.run("mylap/system.toml")` from the folder above the lap, and
    `twinbench.run("system.toml")` from inside it, as the command line does."""
    p = subprocess.run(
        [str(EXE), "lap", str(ROOT / "data/spielberg_lap.csv"), "--track",
         str(ROOT / "data/spielberg_lap_track.csv"), "--out", "mylap"],
        capture_output=True, text=True, cwd=tmp_path,
    )
    assert p.returncode == 0, p.stderr
    monkeypatch.chdir(tmp_path)
    above = twinbench.run("mylap/system.toml", stop=1.0)
    monkeypatch.chdir(tmp_path / "mylap")
    inside = twinbench.run("system.toml", stop=1.0)
    assert same_bits(above.signals["vehicle.v"], inside.signals["vehicle.v"])
    # A relative path parameter is relative to the working directory, as --set is.
    inside = twinbench.run("system.toml", stop=1.0, parameters={"vehicle.track_file": "track.csv"})
    assert same_bits(above.signals["vehicle.v"], inside.signals["vehicle.v"])


def test_version_is_the_workspaces():
    cargo = (ROOT / "Cargo.toml").read_text()
    version = cargo.split("[workspace.package]", 1)[1].split('version = "', 1)[1].split('"', 1)[0]
    assert twinbench.__version__ == version


def test_to_pandas_without_pandas_names_the_extra(monkeypatch):
    import sys

    result = twinbench.run(SYSTEM, stop=0.1)
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas then fails
    with pytest.raises(ImportError, match=r"pip install 'twinbench\[pandas\]'"):
        result.to_pandas()


CTRL_C = """
import sys, twinbench
twinbench.Study(sys.argv[1]).optimize(out=sys.argv[2], threads=2)
print("finished")
"""


def test_ctrl_c_stops_a_study_after_its_generation_and_says_how_to_resume(tmp_path):
    out = tmp_path / "opt"
    # The child starts with SIGINT at its default, as under a terminal: a suite launched in
    # the background by a shell without job control inherits SIGINT ignored, and a Python
    # started so never installs its KeyboardInterrupt handler (the signal would be lost).
    child = subprocess.Popen(
        [sys_executable(), "-c", CTRL_C, str(STUDY), str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    checkpoint = out / "spielberg.checkpoint.json"
    wait_for(checkpoint, child)
    child.send_signal(signal.SIGINT)
    stdout, stderr = child.communicate(timeout=120)
    assert child.returncode != 0
    assert "finished" not in stdout
    assert "interrupt: stopping after the generation under way" in stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("KeyboardInterrupt: interrupted: checkpoint kept"), stderr
    assert "resume=True" in last and "--resume" in last, last
    assert checkpoint.exists()
    # Resumed, it finishes with the Tab. 1 of an uninterrupted study.
    result = twinbench.Study(STUDY).optimize(out=out, threads=2, resume=True)
    assert result["steps"][-1]["name"] == "geometry"


def wait_for(checkpoint, child):
    """Until the running optimisation `child` has written its first checkpoint (at most 2
    minutes; the child still running)."""
    import time

    started = time.monotonic()
    while not checkpoint.exists():
        assert child.poll() is None, child.communicate()
        assert time.monotonic() - started < 120, "no checkpoint after 2 minutes"
        time.sleep(0.05)


def sys_executable():
    import sys

    return sys.executable


def snippets():
    """Every ```python block of the README and docs/, with where it stands."""
    blocks = []
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        lines = doc.read_text().splitlines()
        k = 0
        while k < len(lines):
            if lines[k].strip() == "```python":
                start = k + 1
                k += 1
                while lines[k].strip() != "```":
                    k += 1
                blocks.append((f"{doc.relative_to(ROOT)}:{start}", "\n".join(lines[start:k])))
            k += 1
    return blocks


@pytest.mark.parametrize("where,code", snippets(), ids=[w for w, _ in snippets()])
def test_every_python_snippet_in_the_docs_runs_as_a_script(where, code, tmp_path):
    if "not run by the tests" in code.splitlines()[0]:
        pytest.skip(code.splitlines()[0])
    script = tmp_path / "snippet.py"
    script.write_text(code)
    p = subprocess.run([sys_executable(), str(script)], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 0, f"{where}:\n{p.stderr[-3000:]}"


def test_every_documented_python_m_twinbench_command_parses():
    """`python -m twinbench ...` lines of the README's and docs/' shell blocks parse with the
    package's own argument parser (a renamed flag fails here)."""
    import shlex

    from twinbench.__main__ import _parser

    checked = 0
    for doc in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        shell = False
        for n, line in enumerate(doc.read_text().splitlines(), 1):
            s = line.strip()
            if s.startswith("```"):
                shell = not shell and s[3:] in ("sh", "bash", "console", "shell")
                continue
            if shell and s.startswith("python -m twinbench "):
                words = shlex.split(s[len("python -m twinbench "):], comments=True)
                try:
                    _parser().parse_args(words)
                except SystemExit as e:
                    raise AssertionError(f"{doc.relative_to(ROOT)}:{n}: {s}") from e
                checked += 1
    assert checked >= 2


# ---- red team N15, N26: what the package is handed is checked ----


class _Fixed:
    """An executor whose every task returns `value` (a broken task or cluster)."""

    def __init__(self, value):
        self.value = value

    def submit(self, fn, *args):
        f = concurrent.futures.Future()
        f.set_result(self.value)
        return f


@pytest.mark.parametrize("value", [float("nan"), -1e300, float("inf"), object()])
def test_an_executors_impossible_cost_stops_the_study(value, tmp_path):
    with pytest.raises(twinbench.TwinbenchError, match="candidate 0 of step 1"):
        twinbench.Study(STUDY).optimize(executor=_Fixed(value), out=tmp_path, generations=1, report=False)


def test_a_study_whose_every_candidate_failed_is_an_error(tmp_path):
    with pytest.raises(twinbench.TwinbenchError, match="every one of its 8 candidates failed"):
        twinbench.Study(STUDY).optimize(executor=_Fixed("the FMU crashed"), out=tmp_path, generations=1, report=False)


def test_a_failed_candidate_is_its_message_with_its_kind():
    import pickle

    from twinbench._failure import Failure

    f = Failure("FMU error: instance 'v': no", "fmu")
    assert isinstance(f, str) and f == "FMU error: instance 'v': no" and f.kind == "fmu"
    # A Dask task's result crosses processes pickled: the kind comes with it.
    back = pickle.loads(pickle.dumps(f))
    assert back == f and back.kind == "fmu"
    assert Failure("it broke").kind == "unknown"


def test_a_million_threads_are_refused():
    with pytest.raises(twinbench.TwinbenchError, match="at most 1024"):
        twinbench.Study(STUDY).optimize(threads=10**6, generations=1, report=False)


def test_a_progress_callback_that_raises_stops_the_study(tmp_path):
    seen = []

    def progress(record):
        seen.append(record["generation"])
        raise ValueError("my callback is broken")

    with pytest.raises(ValueError, match="my callback is broken"):
        twinbench.Study(STUDY).optimize(out=tmp_path, progress=progress, report=False)
    assert seen == [1], "stopped after the generation that raised"
    assert (tmp_path / "spielberg.checkpoint.json").exists()


def test_tell_refuses_costs_that_are_not_finite():
    opt = twinbench.Optimizer("cmaes", bounds=[(0.0, 1.0), (0.0, 1.0)], seed=1)
    xs = opt.ask()
    with pytest.raises(twinbench.TwinbenchError, match="is -inf: costs are finite numbers"):
        opt.tell([float("-inf")] + [1.0] * (len(xs) - 1))


def test_a_malformed_digest_says_what_it_is():
    from twinbench import _native

    worker = _native.StudyEvaluatorPy(str(STUDY))
    with pytest.raises(twinbench.TwinbenchError, match="not a twinbench digest"):
        worker.mismatch("{not json")


def test_pack_writes_the_four_fmus_as_the_command_line_does(tmp_path):
    written = twinbench.pack(tmp_path / "fmu")
    assert sorted(p.name for p in written) == ["driver.fmu", "dyno.fmu", "edu.fmu", "vehicle.fmu"]
    assert all(p.is_file() and p.stat().st_size > 0 for p in written)
    # The same from `python -m twinbench pack`, one model by name.
    import sys

    p = subprocess.run(
        [sys.executable, "-m", "twinbench", "pack", "vehicle", "-o", str(tmp_path / "one")],
        capture_output=True,
        text=True,
    )
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "one/vehicle.fmu").is_file()
    assert p.stdout.strip() == str(tmp_path / "one/vehicle.fmu")
    with pytest.raises(twinbench.TwinbenchError, match="vehicel"):
        twinbench.pack(tmp_path / "bad", ["vehicel"])


def test_the_exception_is_twinbenchs_not_the_native_modules():
    assert twinbench.TwinbenchError.__module__ == "twinbench"
    assert repr(twinbench.TwinbenchError("x")) == "TwinbenchError('x')"
    assert f"{twinbench.TwinbenchError.__module__}.{twinbench.TwinbenchError.__qualname__}" == "twinbench.TwinbenchError"


# ---- the fourth red team ----


def test_a_rust_warning_reaches_python_as_a_twinbench_warning(tmp_path, monkeypatch):
    # M13: a warning of the Rust code (here: the store of unpacked FMUs, made writable for
    # everyone, repaired) is a Python warning, not dropped.
    store = tmp_path / "store"
    monkeypatch.setenv("TWINBENCH_CACHE", str(store))
    twinbench.run(SYSTEM, stop=0.01)
    os.chmod(store, 0o777)
    with pytest.warns(twinbench.TwinbenchWarning, match="repaired to mode 700"):
        twinbench.run(SYSTEM, stop=0.01)
    assert os.stat(store).st_mode & 0o777 == 0o700


def test_optimizer_and_evaluate_inputs_are_checked():
    # M15: bounds whose width overflows, a start that is not a number, a penalty that is
    # not a cost: refused, never inf or NaN candidates and costs.
    with pytest.raises(twinbench.TwinbenchError, match="finite width"):
        twinbench.Optimizer("cmaes", [(-1e308, 1e308)])
    with pytest.raises(twinbench.TwinbenchError, match=r"start\[0\] = NaN"):
        twinbench.Optimizer("cmaes", [(0.5, 1.5)] * 2, start=[float("nan"), 1.0])
    with pytest.raises(twinbench.TwinbenchError, match=r"start\[1\] = 2.0"):
        twinbench.Optimizer("ga", [(0.5, 1.5)] * 2, start=[1.0, 2.0])
    study = twinbench.Study(STUDY)
    for penalty in [float("nan"), -1.0, float("inf")]:
        with pytest.raises(twinbench.TwinbenchError, match="a finite number >= 0"):
            study.evaluate(0, [[-5.0, 1.0]], penalty=penalty)
    # M17: a negative thread count and a state that is not JSON are named.
    with pytest.raises(twinbench.TwinbenchError, match=r"threads=-1: a number of threads, 0 or more"):
        study.evaluate(0, [[-5.0, 1.0]], threads=-1)
    opt = twinbench.Optimizer("cmaes", [(0.5, 1.5)] * 2)
    with pytest.raises(twinbench.TwinbenchError, match=r"Optimizer.restore: the state is not the JSON text Optimizer.save\(\) gives"):
        opt.restore("garbage")


# ---- the fifth red team ----


def test_sigterm_stops_python_m_optimize_after_its_generation_and_says_how_to_resume(tmp_path):
    """SIGTERM (a batch system's stop) during `python -m twinbench optimize`: as Ctrl-C on the
    command line, the generation under way finishes, the checkpoint is kept, the message
    names the command that resumes it (this one, with its options), no traceback, exit 130."""
    out = tmp_path / "opt"
    cmd = [sys_executable(), "-m", "twinbench", "optimize", str(STUDY), "--out", str(out),
           "--threads", "2", "--generations", "2", "--no-report", "--quiet"]
    child = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    checkpoint = out / "spielberg.checkpoint.json"
    wait_for(checkpoint, child)
    child.send_signal(signal.SIGTERM)
    stdout, stderr = child.communicate(timeout=120)
    assert child.returncode == 130, stderr
    assert "Traceback" not in stderr, stderr
    last = stderr.strip().splitlines()[-1]
    assert last == (f"interrupted: checkpoint kept ({checkpoint}); resume with "
                    f"`python -m twinbench optimize {STUDY} --resume --out {out} --generations 2 --no-report`"), last
    json.loads(checkpoint.read_text().split('"checkpoint":', 1)[1][:-2])
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]
    # The resume command, as printed (its first word is the Python that runs twinbench).
    resumed = subprocess.run([sys_executable(), *last.split("`")[1].split()[1:], "--threads", "2", "--quiet"],
                             capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "result.json").exists()


def test_the_resume_command_keeps_the_cluster():
    import argparse

    from twinbench.__main__ import _resume_command

    args = argparse.Namespace(study=Path("s.toml"), out=Path("o"), scheduler="tcp://head:8786", local=None,
                              generations=None, optimizer="ga", no_report=False)
    assert _resume_command(args) == ("python -m twinbench optimize s.toml --resume --out o "
                                     "--scheduler tcp://head:8786 --optimizer ga")
    args.scheduler, args.local = None, 3
    assert "--local 3" in _resume_command(args)


def test_an_edited_and_redigested_checkpoint_is_refused_from_python(tmp_path):
    # M14 from Python: a checkpoint whose finished step was edited (its cost after set to 0)
    # and whose digest was made again is refused on resume, naming the step.
    import hashlib

    def stop_in_step_2(record):
        if record["step"] == 2:
            raise RuntimeError("stop here")

    with pytest.raises(RuntimeError, match="stop here"):
        twinbench.Study(STUDY).optimize(out=tmp_path, generations=1, progress=stop_in_step_2, report=False,
                                        threads=2)
    cp = tmp_path / "spielberg.checkpoint.json"
    v = json.loads(cp.read_text())
    assert len(v["checkpoint"]["completed"]) >= 1
    v["checkpoint"]["completed"][0]["cost_after"] = 0.0
    body = json.dumps(v["checkpoint"], separators=(",", ":"))
    cp.write_text('{"sha256":"' + hashlib.sha256(body.encode()).hexdigest() + '","checkpoint":' + body + "}\n")
    with pytest.raises(twinbench.TwinbenchError, match="step 1 'lift' of the checkpoint says its cost after was 0.0"):
        twinbench.Study(STUDY).optimize(out=tmp_path, generations=1, resume=True, report=False, threads=2)


@pytest.mark.parametrize("bounds,says", [
    ((-1e308, 1e308), r"bounds \[-1e\+?308, 1e\+?308\] of 'vehicle.c_lift_front' leave its declared range \[-2, 6\]"),
    ((5.0, 100.0), r"bounds \[5, 100\] of 'vehicle.c_lift_front' leave its declared range \[-2, 6\]"),
    ((1.5, 0.5), r"'vehicle.c_lift_front': bounds \[1.5, 0.5\] are not an interval"),
    ((float("nan"), 1.0), r"'vehicle.c_lift_front': bounds \[NaN, 1\] are not an interval"),
])
def test_profiles_with_hostile_bounds_are_refused_before_a_lap_runs(bounds, says, tmp_path):
    # --profiles steps out to the bounds: bounds past what the FMU declares, reversed or not
    # numbers are refused when the study is read, naming the parameter.
    text = STUDY.read_text().replace("min = 0.2\nmax = 2.5", f"min = {bounds[0]!r}\nmax = {bounds[1]!r}".replace("nan", "nan"), 1)
    text = text.replace('system = "../systems/', f'system = "{ROOT}/systems/').replace(
        'measurement = "../data/', f'measurement = "{ROOT}/data/')
    study = tmp_path / "hostile.toml"
    study.write_text(text)
    with pytest.raises(twinbench.TwinbenchError, match=says) as caught:
        twinbench.Study(study).optimize(out=tmp_path / "o", generations=1, profiles=True, report=False)
    assert "c_lift_front" in str(caught.value)
    assert not (tmp_path / "o" / "hostile.checkpoint.json").exists()


def test_a_study_result_hands_its_fitted_twin_on(tmp_path):
    # The lift step alone, one generation: its result's export_twin writes the FMUs whose
    # start values are the answer; the bare FMUs (no value set) run the lap that the
    # study's system gives with the answer set, bit for bit.
    text = STUDY.read_text()
    text = text[: text.index("# Step 2")].replace('"../', f'"{ROOT.as_posix()}/')
    study = tmp_path / "lift.toml"
    study.write_text(text)
    records = []
    result = twinbench.Study(study).optimize(out=tmp_path / "opt", generations=1, report=False, threads=2,
                                             progress=records.append)
    assert isinstance(result, twinbench.StudyResult) and isinstance(result, dict)
    # Progress: the generation's record, then the joint refinement's, which ends done.
    assert records[0]["phase"] == "generation" and records[0]["generation"] == 1
    refinement = [r for r in records if r["phase"] == "refinement"]
    assert refinement and refinement[-1]["done"] is True, records
    assert refinement[-1]["parameters"] == ["vehicle.c_lift_front", "vehicle.c_lift_rear"]
    assert refinement[-1]["laps"] == result["joint"]["refinement"]["laps"], (refinement, result["joint"]["refinement"])
    summary = result.export_twin(tmp_path / "twin", fmi=[2])
    assert summary["fitted_instances"] == ["vehicle", "driver", "dyno_rl", "dyno_rr", "edu"]
    assert "fmu/vehicle.fmu" in summary["files"] and "fmu/vehicle-fmi3.fmu" not in summary["files"]
    system = (tmp_path / "twin" / "fitted_system.toml").read_text()
    bare = system[: system.index("[parameters]")] + system[system.index("[[check]]"):]
    (tmp_path / "twin" / "bare.toml").write_text(bare)
    fitted = twinbench.run(tmp_path / "twin" / "bare.toml")
    answer = dict(result["parameters_final"])
    assert set(answer) == {"vehicle.c_lift_front", "vehicle.c_lift_rear"}
    original = twinbench.run(Path(result["system"]), parameters=answer)
    for name in ["vehicle.Fz_sum", "vehicle.Fz_fl", "vehicle.v"]:
        assert np.array_equal(fitted.signals[name], original.signals[name]), name
    # A folder holding other files is refused, and they stay.
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    with pytest.raises(twinbench.TwinbenchError, match="not an earlier export-twin output"):
        result.export_twin(tmp_path / "mine")
    assert (tmp_path / "mine" / "notes.txt").read_text() == "mine"


def test_realtime_check_says_what_a_step_does(tmp_path, monkeypatch):
    # Our dyno is clean; a bench's FMUs each get the bench's inputs; the report is the
    # command line's (items with verdicts, the measurement).
    exe = ROOT / "target" / "release" / "twinbench"
    dyno = ROOT / "target" / "fmu" / "dyno.fmu"
    r = twinbench.realtime_check(dyno, duration=1.0, passes=2, executable=exe)
    assert r["clean"] is True, r
    assert r["measurement"]["passes"] == 2 and r["steps_per_pass"] == 1000
    verdicts = {i["name"]: i["verdict"] for i in r["items"]}
    assert verdicts["allocations"] == "clean" and verdicts["system calls"] == "clean"
    assert verdicts["step time"] == "measured"
    bench = twinbench.realtime_check(ROOT / "systems" / "rls_v.toml", duration=2.0, passes=1, executable=exe)
    assert [b["instance"] for b in bench] == ["vehicle", "driver", "dyno_rl", "edu"]
    assert all(b["report"]["clean"] for b in bench)
    # A bad option is refused naming it.
    with pytest.raises(twinbench.TwinbenchError, match="isolate"):
        twinbench.realtime_check(dyno, isolate="none", executable=exe)
    # No twinbench executable: said, not guessed.
    monkeypatch.delenv("TWINBENCH_WORKER_EXE", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(twinbench.TwinbenchError, match="the twinbench executable"):
        twinbench.realtime_check(dyno)
