"""Every relative link in the README and docs/ points at a file or folder of the repository."""
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_relative_links_in_the_docs_resolve() -> None:
    broken = []
    for md in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)", md.read_text(encoding="utf-8")):
            if "://" not in target and not target.startswith("mailto:") and not (md.parent / target).exists():
                broken.append(f"{md.relative_to(ROOT)}: {target}")
    assert not broken, "broken links:\n" + "\n".join(broken)
