"""Every registered command and subcommand explains itself with an example."""

from __future__ import annotations

import argparse

import pytest

from mocapkit.cli.main import build_parser, main


def _commands(
    parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()
) -> list[tuple[str, ...]]:
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out.append((*prefix, name))
                out.extend(_commands(sub, (*prefix, name)))
    return out


COMMANDS = _commands(build_parser())


def test_the_walk_finds_every_command_group() -> None:
    groups = {c[0] for c in COMMANDS}
    assert {"demo", "imu", "suit", "body", "teleop", "viewer"} <= groups
    assert len(COMMANDS) > len(groups)  # and their subcommands


@pytest.mark.parametrize("command", COMMANDS, ids=" ".join)
def test_help_shows_an_example(
    command: tuple[str, ...], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*command, "--help"]) == 0
    text = capsys.readouterr().out
    assert "example" in text.lower(), f"`mocapkit {' '.join(command)} --help` has no example"
    assert f"mocapkit {command[0]}" in text, "the example should show a mocapkit command line"


def test_top_level_help_documents_the_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    assert "exit codes: 0 success, 1 failed on the input" in text
    assert "mocapkit demo" in text


def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--no-such-flag"]) == 2
    assert "unrecognized arguments" in capsys.readouterr().err
