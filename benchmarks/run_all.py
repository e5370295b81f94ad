"""Run every benchmark (``make bench``) and refresh docs/benchmarks.md.

    python -m benchmarks.run_all              # every module, one after the other
    python -m benchmarks.run_all --only imu_filters,demo_timing
    python -m benchmarks.run_all --list       # what would run
    python -m benchmarks.run_all --index-only # rewrite the index of docs/benchmarks.md

Each module runs in its own process (``python -m benchmarks.<name>`` with its defaults),
so one failing or crashing benchmark does not stop the others; its output goes to
``out/bench/<name>.log``. Modules write their own section of docs/benchmarks.md; this
runner then rewrites the index at the top of the file (every ``##`` section with the
commands it quotes) and prints a summary. Exit code 1 if any benchmark failed.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "benchmarks.md"
LOGS = REPO / "out" / "bench"
#: modules that are not benchmarks (the gain tuners are searches: run them on purpose)
NOT_BENCHMARKS = {"__init__", "_docs", "run_all", "tune_gains", "polaris_tune"}
INDEX_START = "<!-- index: written by python -m benchmarks.run_all -->"
INDEX_END = "<!-- end of index -->"


def benchmark_modules() -> list[str]:
    """Names of the runnable benchmark modules (files with a ``__main__`` block)."""
    out = []
    for path in sorted((REPO / "benchmarks").glob("*.py")):
        if path.stem in NOT_BENCHMARKS:
            continue
        if "__main__" in path.read_text():
            out.append(path.stem)
    return out


def run_module(name: str, timeout_s: float) -> tuple[int, float]:
    """Run one module; returns (exit code, seconds). Output to out/bench/<name>.log."""
    LOGS.mkdir(parents=True, exist_ok=True)
    log = LOGS / f"{name}.log"
    t0 = time.perf_counter()
    with log.open("w") as f:
        try:
            code = subprocess.run(
                [sys.executable, "-m", f"benchmarks.{name}"],
                cwd=REPO,
                stdout=f,
                stderr=subprocess.STDOUT,
                timeout=timeout_s,
                check=False,
            ).returncode
        except subprocess.TimeoutExpired:
            f.write(f"\nrun_all: timed out after {timeout_s:.0f} s\n")
            code = 124
    return code, time.perf_counter() - t0


def make_index(text: str) -> str:
    """The index block: one line per ``##`` section with the benchmark commands it quotes."""
    body = text
    if INDEX_START in text:
        body = text[text.index(INDEX_END) + len(INDEX_END) :]
    lines = [INDEX_START, "", "| section | commands |", "|---|---|"]
    for m in re.finditer(r"^## (.+)$", body, flags=re.M):
        title = m.group(1).strip()
        nxt = body.find("\n## ", m.end())
        chunk = body[m.end() : nxt if nxt >= 0 else len(body)]
        cmds = sorted(set(re.findall(r"python -m (benchmarks\.\w+)", chunk)))
        anchor = re.sub(r"[^a-z0-9 -]", "", title.lower()).replace(" ", "-")
        listed = ", ".join(f"`python -m {c}`" for c in cmds) or "(see the section)"
        lines.append(f"| [{title}](#{anchor}) | {listed} |")
    lines += ["", "`make bench` runs them all (`python -m benchmarks.run_all`).", "", INDEX_END]
    return "\n".join(lines)


def write_index(path: Path = DOC) -> Path:
    """Insert or replace the index after the title (first paragraph) of the file."""
    text = path.read_text()
    index = make_index(text)
    if INDEX_START in text:
        start = text.index(INDEX_START)
        end = text.index(INDEX_END) + len(INDEX_END)
        text = text[:start] + index + text[end:]
    else:
        first = text.find("\n## ")
        head, rest = (text, "") if first < 0 else (text[: first + 1], text[first + 1 :])
        text = head.rstrip("\n") + "\n\n" + index + "\n\n" + rest
    path.write_text(text)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--only", default="", help="comma-separated module names")
    ap.add_argument("--skip", default="", help="comma-separated module names")
    ap.add_argument("--list", action="store_true", help="list the modules and exit")
    ap.add_argument("--index-only", action="store_true", help="only rewrite the index")
    ap.add_argument("--timeout-s", type=float, default=3600.0, help="per module")
    args = ap.parse_args(argv)
    modules = benchmark_modules()
    if args.only:
        wanted = [m.strip() for m in args.only.split(",") if m.strip()]
        unknown = sorted(set(wanted) - set(modules))
        if unknown:
            print(f"run_all: unknown module(s) {', '.join(unknown)}; have {', '.join(modules)}")
            return 2
        modules = wanted
    skip = {m.strip() for m in args.skip.split(",") if m.strip()}
    modules = [m for m in modules if m not in skip]
    if args.list:
        print("\n".join(modules))
        return 0
    failed = []
    if not args.index_only:
        for name in modules:
            print(f"run_all: {name} ...", flush=True)
            code, secs = run_module(name, args.timeout_s)
            status = "ok" if code == 0 else f"FAILED (exit {code}, see {LOGS / name}.log)"
            print(f"run_all: {name}: {status} in {secs:.0f} s", flush=True)
            if code != 0:
                failed.append(name)
    print(f"run_all: index written to {write_index()}")
    if failed:
        print(f"run_all: {len(failed)} failed: {', '.join(failed)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
