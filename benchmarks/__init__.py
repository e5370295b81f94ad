"""Benchmarks: runnable modules (``python -m benchmarks.<name>``) that measure mocapkit
against its peers side by side and write the figures into docs/benchmarks.md."""
