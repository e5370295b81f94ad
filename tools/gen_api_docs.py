"""Write docs/api.md from the docstrings of the top-level API (``mocapkit.api``).

python tools/gen_api_docs.py          # rewrite docs/api.md
python tools/gen_api_docs.py --check  # exit 1 if docs/api.md is out of date
"""

from __future__ import annotations

import inspect
import sys
from pathlib import Path

DOC = Path(__file__).resolve().parents[1] / "docs" / "api.md"


def render() -> str:
    from mocapkit import api

    lines = [
        "# Python API",
        "",
        "Generated from the docstrings by `python tools/gen_api_docs.py`; every name is",
        "importable from `mocapkit` itself (`mocapkit.reconstruct`, ...).",
        "",
        inspect.cleandoc(api.__doc__ or ""),
        "",
    ]
    for name in api.__all__:
        obj = getattr(api, name)
        kind = "class" if inspect.isclass(obj) else "def"
        try:
            sig = str(inspect.signature(obj))
        except (TypeError, ValueError):
            sig = ""
        lines += [f"## `{name}`", "", f"```python\n{kind} {name}{sig}\n```", ""]
        lines += [inspect.cleandoc(obj.__doc__ or "(no docstring)"), ""]
    lines += _modules()
    return "\n".join(lines).rstrip() + "\n"


#: the building blocks under the top-level API, in the order of the pipeline
MODULES = (
    "mocapkit.series",
    "mocapkit.imu.filters",
    "mocapkit.imu.streaming",
    "mocapkit.imu.sensor_streams",
    "mocapkit.body.sensor_tree",
    "mocapkit.body.pipeline",
    "mocapkit.body.kinematics",
    "mocapkit.body.streamed",
    "mocapkit.body.identify",
    "mocapkit.markers.reconstruct",
    "mocapkit.markers.streamed",
    "mocapkit.markers.streamed_cleaning",
    "mocapkit.retarget.robot_spec",
    "mocapkit.retarget.run",
    "mocapkit.retarget.streamed",
    "mocapkit.retarget.trajectory_io",
    "mocapkit.retarget.live",
    "mocapkit.io.c3d",
    "mocapkit.io.trc",
    "mocapkit.io.imu_files",
    "mocapkit.io.opensim_table",
    "mocapkit.io.opensense",
    "mocapkit.io.joint_angles_mot",
    "mocapkit.io.bvh",
    "mocapkit.io.foxglove_mcap",
    "mocapkit.io.ros2bag",
    "mocapkit.io.ros2_zenoh",
    "mocapkit.io.lsl",
    "mocapkit.teleop.ros2_link",
    "mocapkit.batch",
)


def _first_paragraph(doc: str | None) -> str:
    text = inspect.cleandoc(doc or "")
    return text.split("\n\n", 1)[0].strip() if text else "(no docstring)"


def _public(mod: object) -> list[tuple[str, object]]:
    """The module's ``__all__``, else the functions and classes it defines."""
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [n for n, o in vars(mod).items() if not n.startswith("_")
                 and (inspect.isfunction(o) or inspect.isclass(o))
                 and getattr(o, "__module__", None) == mod.__name__]  # type: ignore[attr-defined]  # fmt: skip
    out = []
    for n in sorted(names):
        o = getattr(mod, n)
        if inspect.isfunction(o) or inspect.isclass(o):
            out.append((n, o))
    return out


def _modules() -> list[str]:
    import importlib

    lines = ["# Modules", "",
             "The building blocks under the top-level names: each module's public functions",
             "and classes with their signature and the first paragraph of their docstring",
             "(the full docstring: `help(mocapkit.body.streamed.stream_body)`).", ""]  # fmt: skip
    for name in MODULES:
        mod = importlib.import_module(name)
        lines += [f"## `{name}`", "", _first_paragraph(mod.__doc__), ""]
        for n, obj in _public(mod):
            kind = "class" if inspect.isclass(obj) else "def"
            try:
                sig = str(inspect.signature(obj))
            except (TypeError, ValueError):
                sig = ""
            lines += [f"### `{name}.{n}`", "", f"```python\n{kind} {n}{sig}\n```", "",
                      _first_paragraph(obj.__doc__), ""]  # fmt: skip
    return lines


def main() -> int:
    try:
        text = render()
    except ImportError as exc:  # an extra not installed: the page cannot be checked here
        print(f"cannot render the API page: {exc}", file=sys.stderr)
        return 2
    if "--check" in sys.argv:
        return 0 if DOC.exists() and DOC.read_text() == text else 1
    DOC.write_text(text)
    print(f"wrote {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
