"""The wheel works when installed: built from a copy of the sources, installed with
--no-deps into a fresh venv that sees the project's dependencies, and run from outside
the checkout (GLSL and asset specs come from inside the installed packages)."""

import os
import shutil
import site
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from smpl_files import write_official_pickle

pytestmark = pytest.mark.slow  # builds and installs the wheel

ROOT = Path(__file__).resolve().parents[2]
SKIP = shutil.ignore_patterns(
    ".git", ".venv", "out", "build", "*.egg-info", "__pycache__", ".pytest_cache", ".hypothesis", "runs"
)


def _run(cmd, cwd, env=None, timeout=600):
    r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, f"{cmd}: {r.stdout[-2000:]}\n{r.stderr[-3000:]}"
    return r


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv python, venv bin folder, a folder outside the checkout)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    shutil.copytree(ROOT, src, ignore=SKIP)
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(tmp / "dist"),
            str(src),
        ],
        cwd=tmp,
    )
    wheels = list((tmp / "dist").glob("texvocab-*.whl"))
    assert len(wheels) == 1
    venv = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp)
    vpy = venv / "bin" / "python"
    purelib = Path(
        _run(
            [str(vpy), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], cwd=tmp
        ).stdout.strip()
    )
    # the project's dependencies, seen through a plain path entry (no .pth of the editable
    # install runs, so `texvocab` can only come from the wheel): this interpreter's
    # site-packages folders, also those a .pth adds (a venv layered over another's)
    deps = [
        sysconfig.get_path("purelib"),
        *site.getsitepackages(),
        *(p for p in sys.path if Path(p).name == "site-packages" and Path(p).is_dir()),
    ]
    (purelib / "project_deps.pth").write_text("\n".join(dict.fromkeys(deps)) + "\n")
    _run(
        [sys.executable, "-m", "pip", "--python", str(vpy), "install", "--no-deps", "-q", str(wheels[0])],
        cwd=tmp,
    )
    work = tmp / "elsewhere"
    work.mkdir()
    return vpy, venv / "bin", work


def test_wheel_carries_shaders_and_specs_inside_its_packages(installed):
    vpy, _, work = installed
    code = (
        "import texvocab, texvocab_viewer.gl.glsl as glsl, texvocab.io.spec as s;"
        "print(texvocab.__file__); print(glsl.shader_source('mesh.vert')[:8]);"
        "print(sorted(s.load_spec('smpl_model')['keys'])[:2])"
    )
    out = _run([str(vpy), "-c", code], cwd=work).stdout.splitlines()
    assert str(ROOT) not in out[0] and "site-packages" in out[0]
    assert out[1].startswith("#version")
    site_dir = Path(out[0]).parent.parent
    assert not (site_dir / "assets_spec").exists() and not (site_dir / "shaders").exists()
    assert (site_dir / "texvocab" / "assets_spec" / "smpl_model.json").is_file()
    assert (site_dir / "texvocab_viewer" / "shaders" / "mesh.frag").is_file()


def test_the_viewer_is_installed_as_texvocab_viewer_and_nothing_as_app(installed):
    """The viewer's source folder app/ is installed under a name of its own: no top-level
    ``app`` (which would collide with any other), and ``python -m texvocab_viewer`` is the
    viewer's command line."""
    vpy, _, work = installed
    code = (
        "import importlib.util, texvocab_viewer.panels.registry as r;"
        "print(importlib.util.find_spec('app')); print([p.title for p in r.PANELS])"
    )
    out = _run([str(vpy), "-c", code], cwd=work).stdout.splitlines()
    assert out == ["None", "['Pose', '3D view', 'Neural render', 'Vocabulary']"]
    site_dir = Path(
        _run([str(vpy), "-c", "import texvocab_viewer as v; print(v.__file__)"], cwd=work).stdout.strip()
    ).parent.parent
    assert not (site_dir / "app").exists()
    help_text = _run([str(vpy), "-m", "texvocab_viewer", "--help"], cwd=work).stdout
    assert help_text.startswith("usage: python -m texvocab_viewer") and "--neural-worker" in help_text


def test_installed_check_assets_and_shot_run_outside_the_checkout(installed, toy_arrays, monkeypatch):
    _, bindir, work = installed
    model = work / "SMPL_NEUTRAL.pkl"
    write_official_pickle(model, toy_arrays, monkeypatch)
    out = _run([str(bindir / "texvocab"), "check-assets", str(model)], cwd=work).stdout
    assert out.startswith("OK") and "valid smpl model" in out
    env = {**os.environ, "PYOPENGL_PLATFORM": "osmesa"}
    env.pop("DISPLAY", None)
    _run(
        [str(bindir / "texvocab"), "shot", "--pose", "walk", "--size", "160x200", "--out", "shots"],
        cwd=work,
        env=env,
    )
    img = np.asarray(Image.open(work / "shots" / "view3d.png").convert("RGB"))
    assert img.shape == (200, 160, 3)
    assert (img.std(axis=(0, 1)) > 5).all()  # a body was drawn, not a blank frame
