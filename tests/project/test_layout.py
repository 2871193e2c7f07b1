"""The package layout: layers in data-flow order (import-linter), a light top-level
import, the public API the viewer uses, the paper's equation numbering."""

import ast
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_import_contracts_hold():
    """Each texvocab layer imports only from those below it; the viewer (texvocab_viewer)
    only texvocab.pipeline, in layers of its own, and below the command line; texvocab.render
    in layers of its own, without cycles. lint-imports runs in this interpreter, which sees
    the packages as installed here."""
    cmd = [sys.executable, "-c", "from importlinter.cli import lint_imports_command as c; c()", "--no-cache"]
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    contracts = PYPROJECT["tool"]["importlinter"]["contracts"]
    assert f"{len(contracts)} kept, 0 broken" in r.stdout


def test_contract_lists_every_subpackage():
    layers = PYPROJECT["tool"]["importlinter"]["contracts"][0]["layers"]
    subpackages = {
        f"texvocab.{p.name}" for p in (ROOT / "texvocab").iterdir() if (p / "__init__.py").is_file()
    }
    assert subpackages == {name for name in layers if name != "texvocab.errors"}


def test_at_most_ten_modules_at_the_top_of_the_package():
    top = [p.name for p in (ROOT / "texvocab").glob("*.py")]
    assert len(top) <= 10, top


def test_packages_listed_for_the_wheel_are_the_folders():
    """Every folder with an __init__.py under texvocab/ and app/ (installed as
    texvocab_viewer) is listed, and so are the mapped folders (shaders/, assets_spec/)."""
    setup = PYPROJECT["tool"]["setuptools"]
    folders = {
        "texvocab": ROOT / "texvocab",
        "texvocab_viewer": ROOT / setup["package-dir"]["texvocab_viewer"],
    }
    found = {
        ".".join((name, *p.parent.relative_to(folder).parts))
        for name, folder in folders.items()
        for p in folder.rglob("__init__.py")
        if "__pycache__" not in p.parts
    }
    mapped = set(setup["package-dir"])
    assert "app" not in setup["packages"]
    assert set(setup["packages"]) == found | mapped, set(setup["packages"]) ^ (found | mapped)


def test_importing_texvocab_and_its_public_api_loads_neither_torch_nor_gl():
    code = (
        "import sys, texvocab, texvocab.pipeline, texvocab.errors\n"
        "heavy = [m for m in ('torch', 'moderngl', 'OpenGL', 'pyrender', 'imgui_bundle')"
        " if m in sys.modules]\nprint(','.join(heavy))"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == ""


def test_every_public_name_resolves():
    import texvocab.pipeline as api

    for name in api.__all__:
        assert getattr(api, name) is not None, name
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        api.nope  # noqa: B018


def _docstrings():
    for path in sorted((ROOT / "texvocab").rglob("*.py")) + sorted((ROOT / "app").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                doc = ast.get_docstring(node)
                if doc:
                    yield path.relative_to(ROOT), doc


def test_docstrings_cite_the_papers_own_equation_numbers_and_nothing_outside_the_repo():
    """The paper numbers its equations 1-10 in LaTeX source order (docs/method.md's equation map);
    a LaTeX label (eqA, eqNA0, ...) or a path outside the repository means nothing to a
    reader of the installed package."""
    bad = []
    for path, doc in _docstrings():
        for n in re.findall(r"\bEqs?\. ?(\d+)", doc):
            if not 1 <= int(n) <= 10:
                bad.append(f"{path}: Eq. {n}")
        if re.search(r"\beq(A|NA\d|:\w+)\b|Eq\. ?[A-Z]\b|shared/", doc):
            bad.append(f"{path}: {doc[:80]!r}")
    assert not bad, bad


def test_the_manuals_equation_map_names_functions_that_exist():
    """Every `module.function` in docs/method.md's equation table resolves."""
    import importlib

    text = (ROOT / "docs" / "method.md").read_text()
    table = text[text.index("## The paper's equations") :].split("\n## ")[0]
    refs = re.findall(r"`(texvocab\.[\w.]+)`", table)
    assert len(refs) >= 10
    for ref in refs:
        parts = ref.split(".")
        cut = 1
        while cut < len(parts):
            try:
                importlib.import_module(".".join(parts[: cut + 1]))
            except ImportError:
                break
            cut += 1
        obj = importlib.import_module(".".join(parts[:cut]))
        for name in parts[cut:]:
            obj = getattr(obj, name)
