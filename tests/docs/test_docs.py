"""The manual builds, and the front page and the manual speak of the project only.

The mkdocs build runs with ``--strict``: a broken page link, a missing anchor or a page left
out of the nav fails it (``mkdocs.yml``'s ``validation`` turns each into a warning).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
MAX_README_LINES = 250
TWO_COMMANDS = ("./scripts/demo", "./scripts/test")
# A development round or a tracker issue cited by number (the word session or issue, a number).
LOG_WORDS = re.compile(r"(?i)\bsession[- ]?\d+|\bissue #?\d+")
IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)[^)]*\)|<img[^>]*\bsrc=\"([^\"]+)\"")


def tracked(*paths: str) -> list[Path]:
    """The files git tracks under ``paths`` (relative to the repository root)."""
    out = subprocess.run(
        ["git", "ls-files", "-z", "--", *paths], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout
    return [ROOT / p for p in out.split("\0") if p]


def test_mkdocs_builds_strict(tmp_path: Path) -> None:
    site = tmp_path / "site"
    build = ["build", "--strict", "-f", str(ROOT / "mkdocs.yml"), "-d", str(site)]
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", *build], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert run.returncode == 0, (
        "mkdocs build --strict failed (mkdocs>=1.6 belongs to the test extra):\n" + run.stdout + run.stderr
    )
    assert (site / "index.html").is_file()
    assert (site / "results" / "index.html").is_file()


def test_readme_is_a_short_front_page_with_the_two_commands() -> None:
    text = README.read_text(encoding="utf-8")
    lines = text.count("\n") + (not text.endswith("\n"))
    assert lines <= MAX_README_LINES, f"README.md has {lines} lines (at most {MAX_README_LINES})"
    for command in TWO_COMMANDS:
        assert command in text, f"README.md lacks {command}"


def test_no_tracked_file_numbers_development_rounds_or_cites_issues() -> None:
    files = tracked()
    assert README in files
    hits = []
    for path in files:
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:  # a binary file (image, array, checkpoint)
            continue
        for n, line in enumerate(text.splitlines(), 1):
            hits += [f"{path.relative_to(ROOT)}:{n}: {m.group(0)!r}" for m in LOG_WORDS.finditer(line)]
    assert not hits, "development log in the docs:\n" + "\n".join(hits)


def test_every_image_the_readme_shows_exists() -> None:
    refs = [a or b for a, b in IMAGE.findall(README.read_text(encoding="utf-8"))]
    assert refs, "README.md shows no picture"
    local = [r for r in refs if not re.match(r"[a-z]+://", r)]
    missing = [r for r in local if not (ROOT / r).is_file()]
    assert not missing, f"README.md shows images that do not exist: {missing}"
