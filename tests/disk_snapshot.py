"""What a command left on disk: every file under a folder with its size and mtime."""

from pathlib import Path


def snapshot(root: Path) -> dict:
    """Every file under root with its size and modification time (ns)."""
    return {
        str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns)
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }
