"""A study's files sent to Dask workers by their content, not by their path.

A worker of a cluster without a shared disk (Dask on Kubernetes, a cloud cluster, a
colleague's workstation) has none of the coordinator's files. The coordinator therefore
hands each file to Dask once, as a future of its bytes published under a name of the study's
(``twinbench-<client>-<id>-<sha256>``, a Dask dataset: the scheduler keeps the task that makes it,
so the bytes are made again if the worker holding them dies), and every task names the
files it needs by path, digest and that name only (a few hundred bytes per file). A worker looks each digest up in its own
content-addressed store (``TWINBENCH_FILES``, else ``~/.cache/twinbench/files``):

- a file it holds is hashed once per process: a copy with another content (a changed
  byte) is thrown away and fetched again, never used;
- a file it lacks is the coordinator's own path when that holds the same bytes (a shared
  file system: nothing travels), else fetched through Dask (the future's bytes, from
  whichever worker holds them; recomputed from the task graph if that worker died),
  checked against its digest and written atomically, read-only.

The files are then linked into a **mirror**, a folder holding each at the coordinator's
absolute path below it, which the Rust side resolves names in (``tb_files::paths``). A
task also carries the coordinator's twinbench version and platform: a worker with another
is refused with a message naming it (:class:`WorkerRefused`), and the coordinator sends its
tasks to the other workers.
"""

from __future__ import annotations

import errno
import hashlib
import os
import platform
import sys
import threading
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

from . import _native
from ._native import TwinbenchError

# The first element of a shipped study's task argument, and its layout's version.
_TAG = "twinbench-shipment"
_LAYOUT = 1

_lock = threading.Lock()
# Content hashes this process has verified in its store, and the mirrors it has built.
_verified: set = set()
_mirrors: Dict[str, str] = {}


class WorkerRefused(TwinbenchError):
    """A worker that cannot run the study (another twinbench version or platform): the
    coordinator sends its tasks elsewhere. ``worker`` is its Dask address."""

    def __init__(self, message: str, worker: str = ""):
        super().__init__(message)
        self.worker = worker

    def __reduce__(self):
        return (WorkerRefused, (str(self), self.worker))


def platform_name() -> str:
    """What a worker must share with the coordinator to run its FMUs' binaries."""
    return f"{sys.platform}-{platform.machine()}"


def store_dir() -> Path:
    """The worker's content-addressed store of study files."""
    env = os.environ.get("TWINBENCH_FILES")
    if env:
        return Path(env)
    return Path.home() / ".cache" / "twinbench" / "files"


def _sha256_of_file(path: Path) -> Optional[str]:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError:
        return None
    return h.hexdigest()


def _content(data: bytes) -> bytes:
    """A file's bytes as a Dask task's result (kept by the scheduler's graph: recomputed on
    another worker if the one holding them dies)."""
    return data


# ---- the coordinator's side ----


class Shipment:
    """The study's files as tasks name them: per file the coordinator's path, its SHA-256
    and the Dask key of its bytes. ``arg`` is the first argument of every task."""

    def __init__(self, client: Any, loaded: Any, study: str):
        import uuid

        self._client = client
        self._names: List[str] = []
        sweep_orphans(client)
        # The coordinator's client in every name: the next study on the cluster takes off
        # the files of one that died (sweep_orphans).
        ident = f"{client.id}-{uuid.uuid4().hex[:12]}"
        files = []
        self.bytes_per_study = 0
        contents = loaded.contents()
        # The study's own path as the Rust side resolved it (absolute, normalised): the
        # first of its files.
        study = os.fspath(contents[0][0]) if contents else study
        for path, sha in contents:
            path = os.fspath(path)
            name = f"twinbench-{ident}-{sha}"
            files.append((path, sha, name))
            if name in self._names:
                # A file two laps name: sent once.
                continue
            data = Path(path).read_bytes()
            if hashlib.sha256(data).hexdigest() != sha:
                raise TwinbenchError(
                    f"{path} changed since the study was loaded: load it again (twinbench.Study) before sending it to the cluster"
                )
            future = client.submit(_content, data, key=name, pure=False)
            client.publish_dataset(future, name=name)
            self._names.append(name)
            self.bytes_per_study += len(data)
        self.arg = (
            _TAG,
            _LAYOUT,
            os.fspath(study),
            tuple(files),
            _native.__version__,
            platform_name(),
        )

    def close(self) -> None:
        """Take the study's files off the cluster (the workers keep their stores)."""
        for name in self._names:
            try:
                self._client.unpublish_dataset(name)
            except Exception:
                pass
        self._names = []


def _owner(name: str) -> Optional[str]:
    """The client that published a dataset ``twinbench-<client>-<12 hex>-<sha256>``."""
    rest = name[len("twinbench-"):] if name.startswith("twinbench-") else ""
    tail = 1 + 12 + 1 + 64
    if len(rest) <= tail or rest[-65] != "-" or rest[-78] != "-":
        return None
    return rest[:-tail]


def _client_ids(dask_scheduler=None) -> List[str]:
    return list(dask_scheduler.clients)


def sweep_orphans(client: Any) -> List[str]:
    """Take off the cluster the files of coordinators that are gone: one that died (killed,
    crashed, its machine lost) could not take its own off, and the scheduler keeps
    published datasets, their bytes held by a worker, until it restarts. Returns the names
    taken off; best effort (a cluster that does not answer keeps them)."""
    try:
        names = [n for n in client.list_datasets() if _owner(n) is not None]
        if not names:
            return []
        alive = set(client.run_on_scheduler(_client_ids))
    except Exception:
        return []
    gone = []
    for name in names:
        if _owner(name) not in alive:
            try:
                client.unpublish_dataset(name)
                gone.append(name)
            except Exception:
                pass
    return gone


class ShippingExecutor:
    """An executor over a Dask client whose tasks carry the study's :class:`Shipment`
    instead of its path (what the study's native loop submits: ``submit(fn, study,
    digest, *args)``). A task a worker refuses goes to the others."""

    def __init__(self, client: Any, shipment: Shipment):
        self.client = client
        self.shipment = shipment
        self.refused: Dict[str, str] = {}
        self._lock = threading.Lock()

    def submit(self, fn, study, *args):
        return _ShippedTask(self, fn, args)

    def _submit(self, fn, args):
        kwargs = {}
        with self._lock:
            refused = dict(self.refused)
        if refused:
            workers = self.client.scheduler_info(n_workers=-1).get("workers", {})
            allowed = [w for w in workers if w not in refused]
            if not allowed:
                raise TwinbenchError(
                    "no worker of the cluster can run the study: " + "; ".join(refused.values())
                )
            kwargs = {"workers": allowed, "allow_other_workers": False}
        return self.client.submit(fn, self.shipment.arg, *args, pure=False, **kwargs)

    def close(self) -> None:
        self.shipment.close()

    def workers(self) -> int:
        """The workers of the cluster now, less the refused ones."""
        workers = self.client.scheduler_info(n_workers=-1).get("workers", {})
        return len([w for w in workers if w not in self.refused])


class _ShippedTask:
    """One task: resubmitted to the other workers when one refuses it."""

    def __init__(self, executor: ShippingExecutor, fn, args):
        self._executor, self._fn, self._args = executor, fn, args
        self._future = executor._submit(fn, args)

    def result(self, timeout=None):
        while True:
            try:
                return self._future.result(timeout=timeout)
            except WorkerRefused as e:
                import warnings

                with self._executor._lock:
                    first = e.worker not in self._executor.refused
                    self._executor.refused[e.worker] = str(e)
                if first:
                    warnings.warn(f"{e}; its tasks go to the other workers", stacklevel=2)
                self._future = self._executor._submit(self._fn, self._args)

    def cancel(self):
        return self._future.cancel()

    def done(self):
        return self._future.done()


def dask_client(executor: Any) -> Any:
    """The Dask client behind ``executor`` (a ``Client`` or its ``get_executor()``), or
    None for any other executor."""
    if executor is None:
        return None
    mod = type(executor).__module__
    if mod.startswith("distributed"):
        if hasattr(executor, "submit") and hasattr(executor, "scheduler_info"):
            return executor
        client = getattr(executor, "_client", None)
        if client is not None and hasattr(client, "scheduler_info"):
            return client
    return None


def shipping(executor: Any, study: str, loaded: Any) -> Any:
    """``executor`` with the study's files sent by content when it is a Dask cluster's;
    any other executor as it is (its workers read the files at their paths)."""
    client = dask_client(executor)
    if client is None:
        return executor
    return ShippingExecutor(client, Shipment(client, loaded, study))


# ---- the worker's side ----


def is_shipment(study: Any) -> bool:
    return isinstance(study, tuple) and len(study) >= 2 and study[0] == _TAG


def _worker_address() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except Exception:
        return f"process {os.getpid()} on {platform.node()}"


def _fetch(name: str) -> bytes:
    """A file's bytes from the cluster (the dataset the coordinator published)."""
    from distributed import get_client, rejoin, secede

    client = get_client()
    # Waiting on the cluster: give this task's thread back meanwhile (the bytes may have
    # to be made again, on a worker whose threads are all waiting here).
    secede()
    try:
        return client.get_dataset(name).result()
    finally:
        rejoin()


def _open_folder(root: Path, rel: str) -> int:
    """A descriptor of the folder `rel` below `root` (made where missing), reached one
    component at a time without following a symbolic link: a link planted anywhere in the
    store (by someone with write access to it) is refused, never followed out of it."""
    fd = os.open(root, os.O_RDONLY | os.O_DIRECTORY)
    try:
        for part in Path(rel).parts:
            if part in ("", ".", "..", "/"):
                raise TwinbenchError(f"worker {_worker_address()}: {rel!r} is not a plain path below {root}")
            try:
                os.mkdir(part, 0o700, dir_fd=fd)
            except FileExistsError:
                pass
            try:
                nxt = os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=fd)
            except OSError as e:
                if e.errno in (errno.ELOOP, errno.ENOTDIR):
                    raise TwinbenchError(
                        f"worker {_worker_address()}: {root / rel} leads through {part!r}, which is a symbolic link or not a folder: "
                        f"something was planted in the store {root}; remove it (twinbench follows no link there)"
                    ) from e
                raise
            os.close(fd)
            fd = nxt
        return fd
    except BaseException:
        os.close(fd)
        raise


def _write_atomically(path: Path, data: bytes, root: Path) -> None:
    """`path` (below `root`) written whole or not at all, without following a link."""
    folder = _open_folder(root, os.path.relpath(path.parent, root))
    try:
        tmp = f".incoming-{os.getpid()}-{threading.get_ident()}-{path.name}"
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600, dir_fd=folder)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
                os.fchmod(f.fileno(), 0o444)
            os.replace(tmp, path.name, src_dir_fd=folder, dst_dir_fd=folder)
        except BaseException:
            try:
                os.unlink(tmp, dir_fd=folder)
            except OSError:
                pass
            raise
    finally:
        os.close(folder)


def _blob(store: Path, path: str, sha: str, key: str) -> Path:
    """The store's copy of the file of content `sha`, verified; fetched when missing or
    different."""
    blob = store / "sha256" / sha[:2] / sha
    with _lock:
        if sha in _verified and blob.is_file():
            return blob
    if blob.exists():
        if _sha256_of_file(blob) == sha:
            with _lock:
                _verified.add(sha)
            return blob
        # A changed copy (a flipped byte, a truncated write): never used, fetched again.
        import warnings

        warnings.warn(
            f"worker {_worker_address()}: its stored copy of {path} ({blob}) does not have the content {sha}; fetched again"
        )
        try:
            os.chmod(blob, 0o644)
            blob.unlink()
        except OSError:
            pass
    # The coordinator's path when it holds the same bytes here (a shared file system),
    # else the cluster's copy.
    try:
        data = Path(path).read_bytes()
    except OSError:
        data = None
    if data is None or hashlib.sha256(data).hexdigest() != sha:
        data = _fetch(key)
    if hashlib.sha256(data).hexdigest() != sha:
        raise TwinbenchError(
            f"worker {_worker_address()}: {path} arrived with another content than its digest {sha}"
        )
    _write_atomically(blob, data, store)
    with _lock:
        _verified.add(sha)
    return blob


def _link(target: Path, link: Path, root: Path) -> None:
    """`link` (below `root`) made a hard link of `target` (a copy across file systems),
    replacing what was there; no symbolic link on the way is followed."""
    folder = _open_folder(root, os.path.relpath(link.parent, root))
    try:
        try:
            st = os.stat(link.name, dir_fd=folder, follow_symlinks=False)
            if os.path.samestat(st, os.stat(target)):
                # Linked already (a file two laps name; a mirror built before).
                return
        except OSError:
            pass
        tmp = f".{link.name}.{os.getpid()}.{threading.get_ident()}"
        try:
            os.link(target, tmp, dst_dir_fd=folder)
        except OSError:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o444, dir_fd=folder)
            with os.fdopen(fd, "wb") as out, open(target, "rb") as src:
                out.write(src.read())
        os.replace(tmp, link.name, src_dir_fd=folder, dst_dir_fd=folder)
    finally:
        os.close(folder)


def study_path(study: Any) -> str:
    """The path a worker loads a study from: the coordinator's path when the task names
    it by path; for a shipment, the study in this worker's mirror of its files (built once
    per process), after the version and platform check."""
    if not is_shipment(study):
        return study
    _, layout, coordinator_path, files, version, plat = study[:6]
    address = _worker_address()
    for p, sha, _ in files:
        # Names below the mirror and in the store: nothing may climb out of either.
        parts = Path(p).parts
        if not p.startswith("/") or ".." in parts or len(sha) != 64 or not all(c in "0123456789abcdef" for c in sha):
            raise TwinbenchError(
                f"worker {address}: the coordinator named a file {p!r} with digest {sha!r}; expected an absolute path without '..' and a SHA-256 in hexadecimal"
            )
    digests: dict = {}
    for p, sha, _ in files:
        if digests.setdefault(p, sha) != sha:
            raise TwinbenchError(
                f"worker {address}: the coordinator named the file {p!r} twice, with the digests {digests[p]} and {sha}: one path has one content"
            )
    if layout != _LAYOUT:
        raise WorkerRefused(
            f"worker {address}: the coordinator's tasks are of layout {layout}, this twinbench ({_native.__version__}) reads {_LAYOUT}",
            address,
        )
    if version != _native.__version__:
        raise WorkerRefused(
            f"worker {address} runs twinbench {_native.__version__}, the coordinator {version}: install the same version on every worker",
            address,
        )
    if plat != platform_name():
        raise WorkerRefused(
            f"worker {address} is {platform_name()}, the coordinator {plat}: the study's FMUs need the coordinator's platform",
            address,
        )
    ident = hashlib.sha256(repr(sorted((p, s) for p, s, _ in files)).encode()).hexdigest()[:32]
    with _lock:
        done = _mirrors.get(ident)
    if done is not None:
        return done
    # A shared file system: every file is at the coordinator's path with its content here.
    if all(_sha256_of_file(Path(p)) == s for p, s, _ in files):
        with _lock:
            _mirrors[ident] = coordinator_path
        return coordinator_path
    store = store_dir()
    mirror = store / "mirrors" / ident
    try:
        store.mkdir(mode=0o700, parents=True, exist_ok=True)
        # Every file in place first, then the mirror's links (a repaired blob is a new
        # file: the links are made again each time).
        # Each file once (two laps may name one measurement).
        unique = list(dict.fromkeys(files))
        blobs: List[Tuple[str, Path]] = [(p, _blob(store, p, s, k)) for p, s, k in unique]
        for p, blob in blobs:
            _link(blob, mirror / p.lstrip("/"), store)
    except OSError as e:
        # A store it cannot write (full, read-only, not its own): this worker cannot run
        # the study, the others can.
        raise WorkerRefused(
            f"worker {address} cannot keep the study's files in its store {store} ({e.strerror or e}: {e.filename}); set TWINBENCH_FILES to a folder it can write",
            address,
        ) from e
    _native.register_mirror(os.fspath(mirror))
    local = os.fspath(mirror / coordinator_path.lstrip("/"))
    with _lock:
        _mirrors[ident] = local
    return local


def forget() -> None:
    """Forget what this process verified and built (for tests)."""
    with _lock:
        _verified.clear()
        _mirrors.clear()
