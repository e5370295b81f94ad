"""``python -m mocapkit`` == the ``mocapkit`` command."""

from mocapkit.cli.main import run

if __name__ == "__main__":
    run()
