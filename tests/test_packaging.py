"""A wheel, not only an editable install, carries the robot, model and scenario files.

The wheel test builds a wheel from a copy of the source tree and installs it, alone, into a
throwaway venv whose dependencies (drake, numpy, ...) come from this interpreter's
site-packages through a .pth line, so nothing is downloaded or compiled. The scenario then
runs from a folder outside the repository.
"""

import json
import os
import shutil
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA_DIRS = ("robots", "models", "diagrams")


def test_every_code_package_and_data_folder_is_listed():
    """A data folder left out of the list ships only through a path setuptools deprecates (its
    build warns that the folder "would be ignored")."""
    tomllib = pytest.importorskip("tomllib")
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    inits = (REPO / "romoco_drake").rglob("__init__.py")
    on_disk = {".".join(p.parent.relative_to(REPO).parts) for p in inits}
    for folder in DATA_DIRS:
        on_disk |= {".".join(("romoco_drake._data", *d.relative_to(REPO).parts))
                    for d in [REPO / folder, *(REPO / folder).rglob("*")]
                    if d.is_dir() and d.name != "__pycache__"}
    missing = sorted(on_disk - listed)
    assert not missing, f"add {missing} to [tool.setuptools] packages in pyproject.toml"
    no_files = sorted({n for n in listed if n.startswith("romoco_drake._data")} - set(config["package-data"]))
    assert not no_files, f"give {no_files} their files in [tool.setuptools.package-data]"


def _run(args, **kwargs):
    return subprocess.run(args, capture_output=True, text=True, timeout=600, **kwargs)


def _build_wheel(tmp_path: Path) -> Path:
    # A copy, so stale build/ output in the checkout cannot slip into the wheel.
    src = tmp_path / "src"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "*.egg-info", "__pycache__", ".*_cache", ".hypothesis"))
    out = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(tmp_path / "dist"), str(src)])
    if out.returncode != 0 and "satisfies the requirement setuptools" in out.stdout + out.stderr:
        pytest.skip("cannot build a wheel: pip finds no setuptools>=77 for the build backend")
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    (wheel,) = (tmp_path / "dist").glob("romoco_drake-*.whl")
    return wheel


def _venv_with(wheel: Path, tmp_path: Path) -> Path:
    """A venv holding only ``wheel``; everything else resolves to this interpreter's packages."""
    venv = tmp_path / "venv"
    assert _run([sys.executable, "-m", "venv", "--without-pip", str(venv)]).returncode == 0
    python = venv / "bin" / "python"
    purelib = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"])
    # Directories named in a .pth file join sys.path after the venv's own site-packages, and
    # the .pth files inside them (the editable install's finder) are not run.
    borrowed = [p for p in site.getsitepackages() if Path(p).is_dir()]
    Path(purelib.stdout.strip(), "borrowed-dependencies.pth").write_text("\n".join(borrowed) + "\n")
    out = _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
                "--no-index", str(wheel)])
    assert out.returncode == 0, out.stdout[-2000:] + out.stderr[-2000:]
    return venv


@pytest.mark.slow
def test_wheel_install_runs_a_scenario(tmp_path):
    wheel = _build_wheel(tmp_path)
    names = set(zipfile.ZipFile(wheel).namelist())
    for folder in DATA_DIRS:
        expected = {f"romoco_drake/_data/{folder}/{p.relative_to(REPO / folder).as_posix()}"
                    for p in (REPO / folder).rglob("*") if p.is_file()}
        assert expected and expected <= names, sorted(expected - names)
    code = {p.relative_to(REPO).as_posix() for p in (REPO / "romoco_drake").rglob("*.py")}
    assert code <= names, sorted(code - names)

    venv = _venv_with(wheel, tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    probe = _run([str(venv / "bin" / "python"), "-c",
                  "import romoco_drake; from romoco_drake.robots.model import load_robot; "
                  "print(romoco_drake.__file__); print(load_robot('h1')._prepared.path)"],
                 cwd=elsewhere, env=env)
    assert probe.returncode == 0, probe.stderr[-2000:]
    package_file, h1_urdf = (Path(line) for line in probe.stdout.split())
    assert package_file.is_relative_to(venv), f"the wheel is shadowed by {package_file}"
    assert h1_urdf.is_relative_to(venv) and h1_urdf.name == "h1.urdf"

    out = _run([str(venv / "bin" / "romoco"), "run", "g1_stand", "--duration", "0.5", "--json"],
               cwd=elsewhere, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    assert summary["scenario"] == "g1_stand" and summary["fell"] is False
