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


COMMANDS = _commands(build_parser(every=True))


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


def test_placeholder_help_lines_equal_the_modules_own() -> None:
    """main() registers only the named command; the others show main.py's copy of their
    help line, which must stay equal to the module's."""
    full = build_parser(every=True)
    lazy = build_parser()
    (full_sub,) = [a for a in full._actions if isinstance(a, argparse._SubParsersAction)]
    (lazy_sub,) = [a for a in lazy._actions if isinstance(a, argparse._SubParsersAction)]
    full_help = {c.dest: c.help for c in full_sub._choices_actions}
    lazy_help = {c.dest: c.help for c in lazy_sub._choices_actions}
    assert lazy_help == full_help


@pytest.mark.parametrize("argv", [["--help"], ["markers", "--help"], ["imu", "--help"]])
def test_help_imports_no_heavy_package(argv: list[str]) -> None:
    """`mocapkit --help` and a command's help load none of the heavy packages (a module
    check in a fresh interpreter, not a timing)."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from mocapkit.cli.main import main\n"
        f"main({argv!r})\n"
        "heavy = ('numba', 'scipy', 'matplotlib', 'pinocchio', 'rich', 'h5py', 'ezc3d')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip().splitlines()[-1] == "[]", out


def test_every_option_has_help() -> None:
    """Every option and argument of every command says what it is (issue 15: 59 did not)."""
    import argparse

    from mocapkit.cli.main import build_parser

    missing = []

    def walk(parser: argparse.ArgumentParser, path: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, f"{path} {name}")
            elif (
                not isinstance(action, (argparse._HelpAction, argparse._VersionAction))
                and not action.help
            ):
                missing.append(f"{path} {'/'.join(action.option_strings) or action.dest}")

    walk(build_parser(every=True), "mocapkit")
    assert missing == []
