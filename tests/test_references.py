"""Every reference in the code, tests and docs points to a file (and a section) in this repository.

A path such as `controller/fields.py` or `docs/method.md#external-inputs` in a docstring, comment or page
must name a file that exists, and a `#section` must be a heading of that page; relative links between the
pages in docs/ are checked the same way. Documents that live outside the repository are never cited.
"""

from __future__ import annotations

import re
import subprocess
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("controller", "vehicles", "server", "webui", "tests")
PAGES = ("README.md", "CONTRIBUTING.md", "docs")

# A repository path: starts at a top-level folder, ends in a file name with an extension we keep.
PATH_REF = re.compile(
    r"(?<![\w/.-])((?:controller|vehicles|server|webui|tests|docs|docker)/[\w./-]*\.(?:py|md|yaml|sh))"
    r"(#[\w-]+)?"
)
MD_LINK = re.compile(r"\]\(([^)\s#]*)(#[^)\s]+)?\)")
# Spelled in pieces so that this file does not match itself.
OUTSIDE = re.compile(
    "|".join(["MET" + r"HOD\.md", "DES" + r"IGN\.md", "STA" + r"CK\.md", "Pit" + "fall", "issue " + "[0-9]"])
)


def tracked_texts() -> list[Path]:
    """The code, tests and pages to check (not this file, whose examples are broken on purpose)."""
    files = [p for d in SOURCES for p in (ROOT / d).rglob("*.py") if p != Path(__file__).resolve()]
    for page in PAGES:
        path = ROOT / page
        files += sorted(path.rglob("*.md")) if path.is_dir() else ([path] if path.exists() else [])
    return sorted(files)


def slug(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


@cache
def anchors(path: Path) -> frozenset[str]:
    heads = re.findall(r"^#{1,6}\s+(.+?)\s*#*\s*$", path.read_text(), flags=re.MULTILINE)
    return frozenset(slug(h) for h in heads)


def broken_references(path: Path) -> list[str]:
    text = path.read_text()
    bad = []
    for match in PATH_REF.finditer(text):
        target, anchor = ROOT / match.group(1), match.group(2)
        if not target.exists():
            bad.append(f"{match.group(0)}: no such file")
        elif anchor and target.suffix == ".md" and anchor[1:] not in anchors(target):
            bad.append(f"{match.group(0)}: no such section")
    if path.suffix == ".md":
        for match in MD_LINK.finditer(text):
            link, anchor = match.group(1), match.group(2)
            if link.startswith(("http://", "https://", "mailto:")):
                continue
            target = (path.parent / link).resolve() if link else path
            if not target.exists():
                bad.append(f"link {link}: no such file")
            elif anchor and target.suffix == ".md" and anchor[1:] not in anchors(target):
                bad.append(f"link {link}{anchor}: no such section")
    return bad


def test_slugs_follow_github():
    assert slug("Active tracking, eqs. (10)-(11)") == "active-tracking-eqs-10-11"
    assert slug('What "input effort" means') == "what-input-effort-means"


def test_the_checker_finds_a_missing_file_and_a_missing_section(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n\nSee controller/nowhere.py, docs/method.md#no-such-part and [x](#title).\n")
    assert broken_references(page) == [
        "controller/nowhere.py: no such file",
        "docs/method.md#no-such-part: no such section",
    ]


def test_every_path_and_section_named_in_code_tests_and_docs_exists():
    problems = {str(p.relative_to(ROOT)): bad for p in tracked_texts() if (bad := broken_references(p))}
    assert problems == {}


def test_nothing_cites_a_document_outside_the_repository():
    hits = [
        f"{p.relative_to(ROOT)}:{n}: {line.strip()}"
        for p in tracked_texts()
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if OUTSIDE.search(line)
    ]
    assert hits == []


def test_gitignore_lists_no_tracked_file():
    done = subprocess.run(
        ["git", "ls-files", "--cached", "--ignored", "--exclude-standard"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    assert done.stdout.split() == []
