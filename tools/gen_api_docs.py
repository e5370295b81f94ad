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
    return "\n".join(lines).rstrip() + "\n"


def main() -> int:
    text = render()
    if "--check" in sys.argv:
        return 0 if DOC.exists() and DOC.read_text() == text else 1
    DOC.write_text(text)
    print(f"wrote {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
