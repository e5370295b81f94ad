"""``make bench``'s runner: which modules it runs and the index it writes."""

from __future__ import annotations

from pathlib import Path

from benchmarks.run_all import INDEX_END, INDEX_START, benchmark_modules, write_index


def test_every_benchmark_module_is_found_and_helpers_are_not() -> None:
    mods = benchmark_modules()
    assert {"imu_filters", "demo_timing", "suit_loopback", "teleop_pipeline"} <= set(mods)
    assert not {"run_all", "tune_gains", "__init__"} & set(mods)


def test_index_lists_sections_with_their_commands_and_is_rewritten(tmp_path: Path) -> None:
    doc = tmp_path / "benchmarks.md"
    doc.write_text(
        "# Benchmarks\n\nIntro.\n\n## Inertial orientation\n\nCommand: `python -m "
        "benchmarks.imu_filters`.\n\n## Viewer, report and demo\n\nRun "
        "`python -m benchmarks.demo_timing`.\n"
    )
    write_index(doc)
    text = doc.read_text()
    assert text.startswith("# Benchmarks\n\nIntro.\n\n" + INDEX_START)
    assert (
        "| [Inertial orientation](#inertial-orientation) | `python -m benchmarks.imu_filters` |"
        in text
    )
    assert "| [Viewer, report and demo](#viewer-report-and-demo) |" in text
    write_index(doc)  # idempotent: one index, sections untouched
    again = doc.read_text()
    assert again == text
    assert again.count(INDEX_END) == 1
