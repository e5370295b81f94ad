"""The ``mocapkit`` command: parse arguments, call the library, write results. No numerics."""
