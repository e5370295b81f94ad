"""``mocapkit batch``: many files through one single-file command, with a broken file in
the batch, through both engines (a local process pool and a local Ray cluster)."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from mocapkit.batch import LOCK, MANIFEST, run_batch
from mocapkit.cli.main import main
from mocapkit.errors import ConfigError
from tests.conftest import require_peer

TRC = Path(__file__).resolve().parents[1] / "data" / "trc"
GOOD = ("markers_walk_excerpt.trc", "std_walking2_markers_excerpt.trc")


@pytest.fixture
def corpus(tmp_path: Path) -> Path:
    d = tmp_path / "in"
    d.mkdir()
    for name in GOOD:
        shutil.copy(TRC / name, d / name)
    (d / "broken.trc").write_text("PathFileType\t4\t(X/Y/Z)\tbroken.trc\nnot a TRC file\n")
    return d


def _check(result_json: dict, out: Path) -> None:  # type: ignore[type-arg]
    assert (result_json["files"], result_json["ok"], result_json["failed"]) == (3, 2, 1)
    (failure,) = result_json["failures"]
    assert failure["file"].endswith("broken.trc")
    assert "broken.trc" in failure["error"]
    for name in GOOD:
        assert (out / name.replace(".trc", ".mot")).stat().st_size > 0
    rows = [json.loads(line) for line in (out / MANIFEST).read_text().splitlines()]
    assert sorted(r["ok"] for r in rows) == [False, True, True]
    assert all(r["figures"]["frames"] > 0 for r in rows if r["ok"])  # the command's --json
    assert not (out / LOCK).exists()


def test_local_batch_with_a_broken_file(
    corpus: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    argv = ["batch", "markers", str(corpus), "-o", str(out), "--workers", "2", "--json"]
    assert main(argv) == 1  # a file failed: exit 1, the others written
    _check(json.loads(capsys.readouterr().out), out)
    # resumable: the outputs are newer than their inputs, only the broken file is redone
    assert main(argv) == 1
    again = json.loads(capsys.readouterr().out)
    assert (again["skipped"], again["ok"], again["failed"]) == (2, 0, 1)
    assert main([*argv, "--force"]) == 1
    assert json.loads(capsys.readouterr().out)["ok"] == 2


def test_the_batch_writes_what_the_single_file_command_writes(corpus: Path, tmp_path: Path) -> None:
    single = tmp_path / "single.mot"
    assert main(["markers", "reconstruct", str(corpus / GOOD[0]), "-o", str(single)]) == 0
    run_batch("markers", [str(corpus / GOOD[0])], tmp_path / "b")
    batch = tmp_path / "b" / GOOD[0].replace(".trc", ".mot")
    assert batch.read_text().splitlines()[5:] == single.read_text().splitlines()[5:]


def test_a_second_batch_on_the_same_directory_is_refused(corpus: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / LOCK).write_text(str(os.getpid()))  # a live batch holds the directory
    with pytest.raises(ConfigError, match="another batch .* is writing to this directory"):
        run_batch("markers", [str(corpus)], out)
    (out / LOCK).write_text("999999999")  # a crashed batch's lock is taken over
    assert run_batch("markers", [str(corpus / GOOD[0])], out).ok == 1


def test_inputs_that_match_nothing_are_an_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="matches no file"):
        run_batch("markers", [str(tmp_path / "*.c3d")], tmp_path / "o")
    with pytest.raises(ConfigError, match=r"no \.c3d/\.trc file found"):
        run_batch("markers", [str(tmp_path)], tmp_path / "o")


def test_ray_batch_with_a_broken_file(
    corpus: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    require_peer("ray", extra="corpus")
    out = tmp_path / "out"
    argv = ["batch", "markers", str(corpus), "-o", str(out), "--workers", "2", "--json"]
    assert main([*argv, "--engine", "ray"]) == 1
    _check(json.loads(capsys.readouterr().out), out)


def test_batch_retarget_passes_the_robot_through_args(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    """``mocapkit batch retarget DIR -o OUT --args '--robot g1'``: every joint-angle file
    onto G1, one CSV each, the options reaching the single-file command."""
    pytest.importorskip("proxsuite", reason="the robots extra")

    from tests.body.synth import write_walk_mot

    src = tmp_path / "in"
    src.mkdir()
    for k, speed in enumerate((0.8, 1.2)):
        write_walk_mot(src / f"walk{k}.mot", duration_s=2.0, still_s=0.5, speed=speed)
    out = tmp_path / "out"
    code = main(["batch", "retarget", str(src), "-o", str(out), "--args", "--robot g1", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 0, report
    assert (report["files"], report["ok"]) == (2, 2)
    header = (out / "walk0.csv").read_text().splitlines()[0]
    assert "left_knee_joint" in header
    rows = [json.loads(line) for line in (out / MANIFEST).read_text().splitlines()]
    assert all(r["figures"]["robot"] == "g1" for r in rows)


def test_url_inputs_and_outputs_through_fsspec(corpus: Path, tmp_path: Path) -> None:
    """Inputs and the output directory as fsspec URLs: a pattern at a URL, each input
    copied to the worker, each output put at its URL, the manifest beside them, the lock
    held at the URL while the batch runs; resumable (an output that exists is skipped).
    ``memory://`` (one process) and ``file://`` (worker processes) stand in for S3/GCS."""
    require_peer("fsspec", extra="corpus")
    import fsspec

    mem = fsspec.filesystem("memory")
    for p in sorted(corpus.iterdir()):
        mem.pipe(f"/trials/{p.name}", p.read_bytes())
    res = run_batch("markers", ["memory://trials/*.trc"], "memory://results")
    assert (res.files, res.ok, res.failed) == (3, 2, 1)
    failed = res.failures[0]["file"]  # named by its URL
    assert failed.startswith("memory://")
    assert failed.endswith("/trials/broken.trc")
    for name in GOOD:
        assert mem.size(f"/results/{name.replace('.trc', '.mot')}") > 0
    rows = [json.loads(x) for x in mem.cat("/results/" + MANIFEST).decode().splitlines()]
    assert sorted(r["ok"] for r in rows) == [False, True, True]
    assert not mem.exists("/results/" + LOCK)
    again = run_batch("markers", ["memory://trials/*.trc"], "memory://results")
    assert (again.skipped, again.ok, again.failed) == (2, 0, 1)
    assert len(mem.cat("/results/" + MANIFEST).decode().splitlines()) == 4  # appended
    # a lock at the URL: another batch writes there
    mem.pipe("/results/" + LOCK, b"1")
    with pytest.raises(ConfigError, match="another batch is writing there"):
        run_batch("markers", ["memory://trials/*.trc"], "memory://results")
    # worker processes: file:// URLs, local outputs
    out = tmp_path / "out"
    res = run_batch("markers", [f"file://{corpus}"], out, workers=2)
    assert (res.ok, res.failed) == (2, 1)
    assert (out / GOOD[0].replace(".trc", ".mot")).stat().st_size > 0
