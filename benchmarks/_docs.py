"""Write one ``## section`` of docs/benchmarks.md (replaced in place, or appended)."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "benchmarks.md"


def write_section(heading: str, text: str, path: Path = DOC) -> Path:
    """Replace the section titled ``heading`` (``## ...``) by ``text``, or append it."""
    content = (
        path.read_text()
        if path.exists()
        else "# Benchmarks\n\nMeasured figures against peers, with the commands behind them.\n"
    )
    title = heading if heading.startswith("## ") else f"## {heading}"
    section = f"{title}\n\n{text.strip()}\n"
    start = content.find(f"\n{title}\n")
    if start >= 0:
        start += 1
        nxt = content.find("\n## ", start + len(title))
        content = content[:start] + section + ("\n" + content[nxt + 1 :] if nxt >= 0 else "")
    else:
        content = content.rstrip("\n") + "\n\n" + section
    path.write_text(content)
    return path
