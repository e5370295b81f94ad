"""Batch processing of many recordings with the single-file commands (``mocapkit batch``).

Each input is one task: the single-file command (``markers reconstruct``, ``imu run``,
``body angles``, ``retarget``) run in a worker on that file, its output written to the output
directory under the input's name. The engines:

- ``local`` (default): a pool of worker processes on this machine, started with
  ``spawn`` after setting one BLAS/OpenMP thread per worker (two processes that each
  start two BLAS threads on two cores run slower than one);
- ``ray``: the same task as a Ray remote function, on a Ray cluster (``ray_address``) or
  a local one started for the run (needs ``pip install 'mocapkit[corpus]'``).

Inputs and the output directory may be fsspec URLs (``s3://bucket/trials/*.c3d``,
``gs://...``, ``file:///...``; ``pip install 'mocapkit[corpus]'`` and the file system's
own package, e.g. ``s3fs``): each task copies its input to a local temporary file, runs
the command there and puts the output at its URL, so a Ray worker on another machine
needs only the credentials. With a URL output directory the manifest is kept in a local
staging directory and put beside the outputs when the batch ends; an output that exists
there is skipped (no modification times to compare) unless ``force``.

A failing file is one failed row with its message, never fatal to the batch. Every
result is appended to ``manifest.jsonl`` in the output directory as it arrives (input,
output, ok, seconds, figures, error); inputs whose output exists and is newer than the
input are skipped (the batch resumes where it stopped) unless ``force``. A lock file
refuses a second batch writing to the same directory.
"""

from __future__ import annotations

import contextlib
import glob
import io
import json
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

from mocapkit.errors import ConfigError, MissingDependencyError

#: kind -> (input suffixes, output suffix, argv of the single-file command)
KINDS: dict[str, tuple[tuple[str, ...], str, Callable[[str, str], list[str]]]] = {
    "markers": (
        (".c3d", ".trc"),
        ".mot",
        lambda src, out: ["markers", "reconstruct", src, "-o", out, "--json"],
    ),
    "imu": (
        (".csv", ".hdf5", ".h5"),
        ".sto",
        lambda src, out: ["imu", "run", src, "-o", out],
    ),
    "body": (
        (".mat", ".sto", ".csv"),
        ".mot",
        lambda src, out: ["body", "angles", src, "-o", out, "--json"],
    ),
    # the robot comes after '--' (--robot g1); the trajectory as CSV
    "retarget": (
        (".c3d", ".trc", ".mot", ".bvh"),
        ".csv",
        lambda src, out: ["retarget", src, "-o", out, "--json"],
    ),
}
MANIFEST = "manifest.jsonl"
LOCK = ".mocapkit-batch.lock"
_ONE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


@dataclass
class Task:
    """One input and where its output goes (local paths or fsspec URLs)."""

    input: str
    output: str
    argv: list[str]  # the command on local paths (the input's and output's own, or staged)
    kind: str = ""
    extra: tuple[str, ...] = ()


def is_url(path: str | Path) -> bool:
    """An fsspec URL (``s3://...``, ``file:///...``), not a local path."""
    return "://" in str(path)


def _fsspec() -> Any:
    try:
        import fsspec
    except ImportError as exc:
        raise MissingDependencyError(
            f"URL inputs and outputs need fsspec ({exc}): pip install 'mocapkit[corpus]' and "
            "the file system's package (s3fs, gcsfs, ...)"
        ) from exc
    return fsspec


def _expand_url(item: str, suffixes: tuple[str, ...]) -> list[str]:
    fs, path = _fsspec().core.url_to_fs(item)
    if any(ch in path for ch in "*?["):
        found = sorted(fs.glob(path))
        if not found:
            raise ConfigError(f"{item}: the pattern matches no file")
    elif fs.isdir(path):
        found = sorted(p for p in fs.ls(path, detail=False) if Path(p).suffix.lower() in suffixes)
    elif fs.exists(path):
        found = [path]
    else:
        raise ConfigError(f"{item}: no such file or directory")
    return [fs.unstrip_protocol(p) for p in found]


@dataclass
class BatchResult:
    """What a batch did (``as_json`` is ``mocapkit batch --json``)."""

    files: int = 0
    ok: int = 0
    failed: int = 0
    skipped: int = 0
    seconds: float = 0.0
    failures: list[dict[str, str]] = field(default_factory=list)
    rows: list[dict[str, Any]] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        return {
            "files": self.files,
            "ok": self.ok,
            "failed": self.failed,
            "skipped": self.skipped,
            "seconds": round(self.seconds, 3),
            "failures": self.failures,
        }


def expand_inputs(inputs: Sequence[str], kind: str) -> list[str]:
    """Files from directories (the kind's suffixes), globs, ``@list.txt`` files (one path
    per line), fsspec URLs (a file, a directory or a pattern) and plain paths; sorted,
    unique. A pattern that matches nothing is an error."""
    suffixes = KINDS[kind][0]
    out: list[Path] = []
    urls: list[str] = []
    for item in inputs:
        if is_url(item):
            urls += _expand_url(item, suffixes)
            continue
        if item.startswith("@"):
            listed = Path(item[1:])
            if not listed.is_file():
                raise ConfigError(f"{item}: the list file {listed} does not exist")
            lines = [ln.strip() for ln in listed.read_text().splitlines()]
            for ln in (ln for ln in lines if ln and not ln.startswith("#")):
                if is_url(ln):
                    urls.append(ln)
                else:
                    out.append(Path(ln))
            continue
        p = Path(item)
        if p.is_dir():
            out += sorted(f for f in p.iterdir() if f.suffix.lower() in suffixes)
        elif any(ch in item for ch in "*?["):
            matched = sorted(Path(m) for m in glob.glob(item, recursive=True))
            if not matched:
                raise ConfigError(f"{item}: the pattern matches no file")
            out += matched
        else:
            out.append(p)
    unique = sorted(dict.fromkeys([*(str(p.resolve()) for p in out), *urls]))
    if not unique:
        raise ConfigError(
            f"inputs: no {'/'.join(suffixes)} file found in {', '.join(inputs)} for '{kind}'"
        )
    return unique


def plan(
    kind: str, inputs: Sequence[str], outdir: str | Path, extra: Sequence[str], force: bool
) -> tuple[list[Task], list[str]]:
    """The tasks to run and the inputs skipped (an output newer than its input; at a URL
    output directory, an output that exists)."""
    _, suffix, argv = KINDS[kind]
    tasks, skipped = [], []
    names: dict[str, str] = {}
    remote_out = is_url(outdir)
    out_fs = _fsspec().core.url_to_fs(str(outdir))[0] if remote_out else None
    for src in inputs:
        where = PurePosixPath(src.split("://", 1)[-1]) if is_url(src) else Path(src)
        name = where.stem + suffix
        if name in names:  # two inputs with one stem: keep both outputs apart
            name = f"{where.parent.name}_{where.stem}{suffix}"
        names[name] = src
        out = f"{str(outdir).rstrip('/')}/{name}" if remote_out else str(Path(outdir) / name)
        if not force and _up_to_date(src, out, out_fs):
            skipped.append(src)
            continue
        tasks.append(Task(src, out, [*argv(src, out), *extra], kind, tuple(extra)))
    # largest first: the long files start early and the short ones fill the gaps at the
    # end, so no worker idles while another finishes a long file alone
    tasks.sort(key=lambda t: -_size(t.input))
    return tasks, skipped


def _up_to_date(src: str, out: str, out_fs: Any) -> bool:
    if out_fs is not None:
        return bool(out_fs.exists(_fsspec().core.url_to_fs(out)[1]))
    o = Path(out)
    if is_url(src):
        return o.exists()
    s = Path(src)
    return o.exists() and s.exists() and o.stat().st_mtime >= s.stat().st_mtime


def _size(path: str) -> int:
    try:
        if is_url(path):
            fs, p = _fsspec().core.url_to_fs(path)
            return int(fs.size(p) or 0)
        return Path(path).stat().st_size
    except (OSError, ValueError):
        return 0


def run_task(task: Task) -> dict[str, Any]:
    """Run one single-file command in this process; never raises: a failure is a row.
    URL inputs and outputs are staged through a local temporary directory."""
    from mocapkit.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    try:
        with (
            contextlib.redirect_stdout(out),
            contextlib.redirect_stderr(err),
            _staged(task) as (argv, local_out),
        ):
            code = main(argv)
            if code == 0 and is_url(task.output):
                fs, path = _fsspec().core.url_to_fs(task.output)
                fs.put(local_out, path)
    except BaseException as exc:  # a batch row, whatever happened
        code, err = 1, io.StringIO(f"{type(exc).__name__}: {exc}")
    seconds = time.perf_counter() - t0
    figures: dict[str, Any] = {}
    text = out.getvalue().strip()
    if text.startswith("{"):
        with contextlib.suppress(json.JSONDecodeError):
            figures = json.loads(text)
    lines = [ln for ln in err.getvalue().splitlines() if "error" in ln.lower()]
    error = lines[-1] if lines else err.getvalue().strip().splitlines()[-1:] or [""]
    return {
        "input": task.input,
        "output": task.output if code == 0 else None,
        "ok": code == 0,
        "seconds": round(seconds, 3),
        "figures": figures,
        "error": None if code == 0 else (error if isinstance(error, str) else " ".join(error)),
    }


@contextlib.contextmanager
def _staged(task: Task) -> Iterator[tuple[list[str], str]]:
    """The task's command on local paths and its local output: a URL input copied to a
    temporary directory first; a URL output written there (the caller puts it at its URL
    when the command succeeded)."""
    if not (is_url(task.input) or is_url(task.output)):
        yield task.argv, task.output
        return
    import tempfile

    fsspec = _fsspec()
    with tempfile.TemporaryDirectory(prefix="mocapkit-batch-") as tmp:
        src = task.input
        if is_url(src):
            fs, path = fsspec.core.url_to_fs(src)
            src = str(Path(tmp) / PurePosixPath(path).name)
            fs.get(path, src)
        dst = str(Path(tmp) / ("out_" + PurePosixPath(task.output.split("://", 1)[-1]).name))
        dst = dst if is_url(task.output) else task.output
        yield [*KINDS[task.kind][2](src, dst), *task.extra], dst


def _one_thread_env() -> None:
    for name in _ONE_THREAD:
        os.environ[name] = "1"


def _local(tasks: list[Task], workers: int) -> Iterator[dict[str, Any]]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    if workers == 1:
        for t in tasks:
            yield run_task(t)
        return
    _one_thread_env()  # inherited by the spawned workers before they import numpy
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=ctx) as pool:
        futures = [pool.submit(run_task, t) for t in tasks]
        for f in as_completed(futures):
            yield f.result()


def _ray(tasks: list[Task], workers: int, address: str | None) -> Iterator[dict[str, Any]]:
    try:
        import ray
    except ImportError as exc:
        raise MissingDependencyError(
            "--engine ray needs Ray: pip install 'mocapkit[corpus]' (or use --engine local)"
        ) from exc
    started = False
    if not ray.is_initialized():
        kwargs: dict[str, Any] = {"log_to_driver": False}
        if address:  # a remote cluster's workers get the thread limits with the job
            env = {"env_vars": {name: "1" for name in _ONE_THREAD}}
            ray.init(address=address, runtime_env=env, **kwargs)
        else:  # a local cluster's workers inherit this environment (no per-job runtime
            _one_thread_env()  # environment to build: that cost 0.1 s a file)
            ray.init(num_cpus=workers, include_dashboard=False, **kwargs)
        started = True
    try:
        remote = ray.remote(num_cpus=1)(run_task)
        pending = [remote.remote(t) for t in tasks]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        if started:
            ray.shutdown()


@contextlib.contextmanager
def _lock(outdir: Path) -> Iterator[None]:
    lock = outdir / LOCK
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        pid = lock.read_text().strip() or "?"
        alive = pid.isdigit() and _alive(int(pid))
        if alive:
            raise ConfigError(
                f"-o {outdir}: another batch (pid {pid}) is writing to this directory; wait "
                "for it or choose another output directory"
            ) from None
        lock.unlink(missing_ok=True)  # a crashed batch's lock: take it over
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    try:
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        yield
    finally:
        lock.unlink(missing_ok=True)


@contextlib.contextmanager
def _output_dir(outdir: str | Path) -> Iterator[Path]:
    """The local directory holding the lock and the manifest: the output directory itself,
    or for a URL a staging directory whose manifest is put beside the outputs at the end
    (appended to the one there), with a lock object at the URL while the batch runs."""
    if not is_url(outdir):
        out = Path(outdir)
        out.mkdir(parents=True, exist_ok=True)
        with _lock(out):
            yield out
        return
    import tempfile

    fs, root = _fsspec().core.url_to_fs(str(outdir))
    lock, manifest = f"{root.rstrip('/')}/{LOCK}", f"{root.rstrip('/')}/{MANIFEST}"
    if fs.exists(lock):
        raise ConfigError(
            f"-o {outdir}: another batch is writing there ({LOCK} exists); wait for it, or "
            "remove the lock if that batch is gone"
        )
    fs.makedirs(root, exist_ok=True)
    fs.pipe(lock, str(os.getpid()).encode())
    try:
        with tempfile.TemporaryDirectory(prefix="mocapkit-batch-") as tmp:
            local = Path(tmp)
            if fs.exists(manifest):
                fs.get(manifest, str(local / MANIFEST))
            try:
                yield local
            finally:
                fs.put(str(local / MANIFEST), manifest)
    finally:
        fs.rm(lock)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def run_batch(
    kind: str,
    inputs: Sequence[str],
    outdir: str | Path,
    extra: Sequence[str] = (),
    workers: int = 1,
    engine: str = "local",
    ray_address: str | None = None,
    force: bool = False,
    on_result: Callable[[dict[str, Any], int, int], None] | None = None,
) -> BatchResult:
    """Run the batch (see the module docstring); ``on_result(row, done, total)`` is called
    as each file finishes."""
    if kind not in KINDS:
        raise ConfigError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    if engine not in ("local", "ray"):
        raise ConfigError(f"--engine: expected local or ray, got {engine!r}")
    if workers < 1:
        raise ConfigError(f"--workers: expected at least 1, got {workers}")
    files = expand_inputs(inputs, kind)
    tasks, skipped = plan(kind, files, outdir, extra, force)
    result = BatchResult(files=len(files), skipped=len(skipped))
    t0 = time.perf_counter()
    with _output_dir(outdir) as out, open(out / MANIFEST, "a") as manifest:
        rows = _local(tasks, workers) if engine == "local" else _ray(tasks, workers, ray_address)
        for row in rows:
            manifest.write(json.dumps(row) + "\n")
            manifest.flush()
            result.rows.append(row)
            if row["ok"]:
                result.ok += 1
            else:
                result.failed += 1
                result.failures.append({"file": row["input"], "error": row["error"] or ""})
            if on_result is not None:
                on_result(row, len(result.rows), len(tasks))
    result.seconds = time.perf_counter() - t0
    return result
