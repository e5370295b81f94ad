"""Batch processing of many recordings with the single-file commands (``mocapkit batch``).

Each input is one task: the single-file command (``markers reconstruct``, ``imu run``,
``body angles``, ``retarget``) run in a worker on that file, its output written to the output
directory under the input's name. The engines:

- ``local`` (default): a pool of worker processes on this machine, started with
  ``spawn`` after setting one BLAS/OpenMP thread per worker (two processes that each
  start two BLAS threads on two cores run slower than one);
- ``ray``: the same task as a Ray remote function, on a Ray cluster (``ray_address``) or
  a local one started for the run (needs ``pip install 'mocapkit[corpus]'``).

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
from pathlib import Path
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
    """One input and where its output goes."""

    input: str
    output: str
    argv: list[str]


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


def expand_inputs(inputs: Sequence[str], kind: str) -> list[Path]:
    """Files from directories (the kind's suffixes), globs, ``@list.txt`` files (one path
    per line) and plain paths; sorted, unique. A pattern that matches nothing is an error."""
    suffixes = KINDS[kind][0]
    out: list[Path] = []
    for item in inputs:
        if item.startswith("@"):
            listed = Path(item[1:])
            if not listed.is_file():
                raise ConfigError(f"{item}: the list file {listed} does not exist")
            lines = [ln.strip() for ln in listed.read_text().splitlines()]
            out += [Path(ln) for ln in lines if ln and not ln.startswith("#")]
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
    unique = sorted(dict.fromkeys(p.resolve() for p in out))
    if not unique:
        raise ConfigError(
            f"inputs: no {'/'.join(suffixes)} file found in {', '.join(inputs)} for '{kind}'"
        )
    return unique


def plan(
    kind: str, inputs: Sequence[Path], outdir: Path, extra: Sequence[str], force: bool
) -> tuple[list[Task], list[Path]]:
    """The tasks to run and the inputs skipped (an output newer than its input)."""
    _, suffix, argv = KINDS[kind]
    tasks, skipped = [], []
    names: dict[str, Path] = {}
    for src in inputs:
        name = src.stem + suffix
        if name in names:  # two inputs with one stem: keep both outputs apart
            name = f"{src.parent.name}_{src.stem}{suffix}"
        names[name] = src
        out = outdir / name
        if (
            not force
            and out.exists()
            and src.exists()
            and out.stat().st_mtime >= src.stat().st_mtime
        ):
            skipped.append(src)
            continue
        tasks.append(Task(str(src), str(out), [*argv(str(src), str(out)), *extra]))
    # largest first: the long files start early and the short ones fill the gaps at the
    # end, so no worker idles while another finishes a long file alone
    tasks.sort(key=lambda t: -Path(t.input).stat().st_size if Path(t.input).exists() else 0)
    return tasks, skipped


def run_task(task: Task) -> dict[str, Any]:
    """Run one single-file command in this process; never raises: a failure is a row."""
    from mocapkit.cli.main import main

    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(task.argv)
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
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    files = expand_inputs(inputs, kind)
    tasks, skipped = plan(kind, files, out, extra, force)
    result = BatchResult(files=len(files), skipped=len(skipped))
    t0 = time.perf_counter()
    with _lock(out), open(out / MANIFEST, "a") as manifest:
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
