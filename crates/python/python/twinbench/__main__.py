"""``python -m twinbench optimize STUDY`` on a Dask cluster; ``python -m twinbench pack``.

    python -m twinbench optimize studies/spielberg.toml --local 2
    python -m twinbench optimize studies/spielberg.toml --scheduler tcp://head:8786

``--local N`` starts a LocalCluster of N worker processes (one thread each);
``--scheduler`` joins a running cluster (every worker needs twinbench installed in the
same version; the study's files travel with the tasks). Without either, the candidates
run on this machine's threads, as ``twinbench optimize``. A line per generation on stderr
says the step, the generation, the candidates done, the best cost and the workers
(``--quiet``: none). The output folder gets the same files as the command
line's (checkpoint, result.json, table1.json, the report); ``--resume`` continues from
its checkpoint.
"""

from __future__ import annotations

import argparse
import json
import shlex
import signal
import sys
import time
from pathlib import Path

from . import Study, TwinbenchError, pack


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m twinbench", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    o = sub.add_parser("optimize", help="run an optimisation study, optionally on a Dask cluster")
    o.add_argument("study", type=Path, help="the study file (TOML)")
    where = o.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://head:8786")
    where.add_argument("--local", metavar="N", type=int, help="a Dask LocalCluster of N worker processes")
    o.add_argument("--threads-per-worker", type=int, default=1, help="threads of each LocalCluster worker (default 1)")
    o.add_argument("--threads", type=int, default=0, help="local threads (default: all cores)")
    o.add_argument("--out", "-o", type=Path, default=Path("target/optimize"), help="output folder")
    o.add_argument("--resume", action="store_true", help="continue from the checkpoint")
    o.add_argument("--generations", type=int, help="override every step's generations")
    o.add_argument("--optimizer", choices=["ga", "cmaes"], help="override the study's optimiser")
    o.add_argument("--force", action="store_true", help="optimise even when measurement and twin do not belong together")
    o.add_argument("--no-report", action="store_true", help="skip Tab. 1 and the plots")
    o.add_argument("--profiles", action="store_true", help="profile likelihood of every parameter (its laps on the cluster too)")
    o.add_argument("--bootstrap", type=int, default=0, metavar="N", help="a moving-block bootstrap of the answer with N refits (a check of the intervals)")
    o.add_argument("--json", action="store_true", help="print the result as JSON")
    o.add_argument("--quiet", "-q", action="store_true", help="no line per generation on stderr")
    k = sub.add_parser("pack", help="pack twinbench's FMUs (vehicle, driver, dyno, edu) as `twinbench pack` does")
    k.add_argument("models", nargs="*", help="the models to pack (default: all four)")
    k.add_argument("--out", "-o", type=Path, help="output folder (default: ~/.local/share/twinbench/fmu)")
    return p


def _pack(args: argparse.Namespace) -> int:
    for path in pack(args.out, args.models or None):
        print(path)
    return 0


def _optimize(args: argparse.Namespace) -> int:
    study = Study(args.study)
    client = cluster = None
    try:
        if args.local is not None or args.scheduler is not None:
            try:
                from dask.distributed import Client, LocalCluster
            except ImportError:
                print("error: --local and --scheduler need dask[distributed] (pip install 'dask[distributed]')", file=sys.stderr)
                return 2
            if args.local is not None:
                if args.local < 1:
                    print(f"error: --local {args.local}: at least one worker", file=sys.stderr)
                    return 2
                cluster = LocalCluster(
                    n_workers=args.local,
                    threads_per_worker=args.threads_per_worker,
                    processes=True,
                    dashboard_address=None,
                )
                client = Client(cluster)
            else:
                client = Client(args.scheduler)
        executor = client.get_executor() if client is not None else None
        started = time.perf_counter()

        def progress(r):
            # One line per generation on stderr (stdout keeps the table or the JSON).
            workers = f", {r['workers']} workers" if "workers" in r else ""
            print(
                f"step {r['step']} {r['step_name']}: generation {r['generation']} of {r['generations']}, "
                f"{r['evaluations']} candidates done, best cost {r['best_cost']:.6g}{workers}",
                file=sys.stderr,
                flush=True,
            )

        result = study.optimize(
            progress=None if args.quiet else progress,
            executor=executor,
            threads=args.threads,
            resume=args.resume,
            generations=args.generations,
            optimizer=args.optimizer,
            out=args.out,
            force=args.force,
            report=not args.no_report,
            profiles=args.profiles,
            bootstrap=args.bootstrap,
        )
        wall = time.perf_counter() - started
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        table = args.out / "table1.md"
        if not args.no_report and table.exists():
            print(table.read_text())
        where = f"Dask ({args.scheduler or f'LocalCluster of {args.local}'})" if client is not None else "local threads"
        print(f"{result['simulations']} full-lap simulations here, candidates on {where}, {wall:.1f} s")
        print(f"result      {args.out / 'result.json'}")
        page = args.out / "report.html"
        if not args.no_report and page.exists():
            # The page to open first, or to hand on: the whole report on one page.
            print(f"page        {page}")
    return 0


def _resume_command(args: argparse.Namespace) -> str:
    """The command that continues an interrupted study where it stopped (on the same
    cluster)."""
    words = ["python", "-m", "twinbench", "optimize", str(args.study), "--resume", "--out", str(args.out)]
    if args.scheduler is not None:
        words += ["--scheduler", args.scheduler]
    elif args.local is not None:
        words += ["--local", str(args.local)]
    if args.generations is not None:
        words += ["--generations", str(args.generations)]
    if args.optimizer is not None:
        words += ["--optimizer", args.optimizer]
    if args.no_report:
        words.append("--no-report")
    return " ".join(shlex.quote(w) for w in words)


def _interrupted(args: argparse.Namespace) -> int:
    """Ctrl-C or SIGTERM during a study: as the command line says it, without a traceback:
    where the checkpoint is and the command that resumes it; exit code 130."""
    checkpoints = sorted(args.out.glob("*.checkpoint.json")) if args.out.is_dir() else []
    kept = f"checkpoint kept ({checkpoints[0]}); " if checkpoints else "no generation was finished; "
    print(f"interrupted: {kept}resume with `{_resume_command(args)}`", file=sys.stderr)
    return 130


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "optimize":
            # SIGTERM (a batch system's or a container's stop) as Ctrl-C: the study stops
            # after the generation under way, its checkpoint kept.
            signal.signal(signal.SIGTERM, signal.default_int_handler)
            try:
                return _optimize(args)
            except KeyboardInterrupt:
                return _interrupted(args)
        if args.command == "pack":
            return _pack(args)
    except TwinbenchError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 2


if __name__ == "__main__":
    sys.exit(main())
