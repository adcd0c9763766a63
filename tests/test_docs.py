"""The code and the docs cite sections of docs/*.md by name (`docs/extraction.md, "Radius"`); a
section renamed or moved to another page leaves such a citation pointing nowhere. Every citation
names a heading of that page, or a bold paragraph label in it (`**A short stroke.**`).
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# `extraction.md, "Radius"`, `extraction.md ("Turned views")`, `[docs/x.md](docs/x.md), "Speed"`
CITATION = re.compile(r'(\w+\.md)\]?(?:\([^)]*\))?\s*,?\s*\(?"([^"]+)"')
# a line break inside a comment or docstring, with the next line's comment marker
WRAP = re.compile(r"\n\s*(?:#+|//+!?)?\s*")


def _tracked(*suffixes: str) -> list[Path]:
    listed = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [ROOT / name for name in listed.split() if name.endswith(suffixes)]


def _anchors(page: Path) -> list[str]:
    text = page.read_text()
    headings = [line.lstrip("#").strip() for line in text.splitlines() if line.startswith("#")]
    labels = [label.strip().rstrip(".") for label in re.findall(r"\*\*([^*]+)\*\*", text)]
    return [" ".join(anchor.split()) for anchor in headings + labels]


def test_every_cited_section_of_the_docs_exists():
    pages = {page.name: _anchors(page) for page in (ROOT / "docs").glob("*.md")}
    assert "extraction.md" in pages
    missing, cited = [], 0
    for source in _tracked(".py", ".pyi", ".rs", ".md"):
        if source == Path(__file__).resolve():
            continue  # its own examples of the pattern
        text = WRAP.sub(" ", source.read_text(errors="ignore"))
        for match in CITATION.finditer(text):
            page, section = match.group(1), " ".join(match.group(2).split())
            if page not in pages:
                continue
            cited += 1
            if not any(anchor.startswith(section) for anchor in pages[page]):
                missing.append(f"{source.relative_to(ROOT)}: {page}, {section!r}")
    assert cited > 100, f"only {cited} citations found: the pattern no longer reads them"
    assert not missing, "citations of sections that do not exist:\n" + "\n".join(missing)
