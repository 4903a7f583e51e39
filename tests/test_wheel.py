"""The distribution ships what its commands need (README "Installing without the Makefile"): a wheel built from
this checkout, installed into a fresh environment, runs ``haptify simulate``, ``haptify-conform --lint`` and
``haptify registry serve`` from outside the source tree.

The fresh environment gets the wheel without its dependencies; those (numpy, pyarrow, …) are reached through a
``.pth`` line naming the project environment's site-packages, where the editable install's import hooks do
not run, so every import of ``haptify*`` resolves to the installed wheel. Nothing is downloaded.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import sysconfig
import time
import urllib.request
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("haptify", "haptify_schemas", "haptify_tools", "haptify_conform", "haptify_mutants")
SOURCES = ("pyproject.toml", "README.md", "reference", "schemas", "tools", "conformance")  # what the build reads

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The ``bin`` folder of a fresh environment holding only the wheel built from this checkout."""
    root = tmp_path_factory.mktemp("wheel")
    source = root / "source"  # a copy: an in-tree build would reuse a stale build/ folder
    source.mkdir()
    for name in SOURCES:
        if (REPO / name).is_dir():
            shutil.copytree(REPO / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
        else:
            shutil.copy2(REPO / name, source / name)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(root / "dist"),
            str(source),
        ],
        check=True,
        capture_output=True,
        text=True,
        timeout=600,
    )
    (wheel,) = (root / "dist").glob("haptify-*.whl")
    env_dir = root / "env"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    site = Path(
        subprocess.run(
            [str(env_dir / "bin" / "python"), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    )
    (site / "project-dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n", encoding="utf-8")
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(env_dir / "bin" / "python"), "install", "--quiet", "--no-deps", str(wheel)],
        check=True,
        capture_output=True,
        text=True,
        timeout=600,
    )
    return env_dir / "bin"


def run(bin_dir: Path, *args: str, cwd: Path, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(bin_dir / args[0]), *args[1:]],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "PYTHONPATH": ""},
    )


def test_every_package_is_imported_from_the_wheel(installed, tmp_path):
    code = "import json, importlib; print(json.dumps({p: importlib.import_module(p).__file__ for p in %r}))" % (PACKAGES,)
    proc = run(installed, "python", "-c", code, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    files = json.loads(proc.stdout)
    assert all(str(installed.parent) in f for f in files.values()), files


def test_simulate_runs_from_the_wheel(installed, tmp_path):
    proc = run(
        installed,
        "haptify",
        "simulate",
        "--preset",
        "touch",
        "--protocol",
        "free_space",
        "--reps",
        "1",
        "--no-rig-trials",
        "--duration",
        "free_space=3",
        "-o",
        str(tmp_path / "sim"),
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    session = json.loads((tmp_path / "sim" / "session" / "session.json").read_text(encoding="utf-8"))
    assert [t["protocol"] for t in session["trials"]] == ["free_space"]
    proc = run(installed, "haptify", "validate", str(tmp_path / "sim" / "session"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_conformance_lint_runs_from_the_wheel(installed, tmp_path):
    proc = run(installed, "haptify-conform", "--lint", "--suite", str(REPO), cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_registry_serves_its_pages_from_the_wheel(installed, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = subprocess.Popen(
        [str(installed / "haptify"), "registry", "serve", "--data", str(tmp_path / "data"), "--port", str(port)],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        env={**os.environ, "PYTHONPATH": ""},
    )
    try:
        deadline, page = time.monotonic() + 60, None
        while page is None and time.monotonic() < deadline and server.poll() is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as response:
                    page = response.read().decode()
            except OSError:
                time.sleep(0.3)
        assert page is not None, server.stdout.read().decode() if server.poll() is not None else "no answer in 60 s"
        assert "<html" in page.lower()
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/static/registry.css", timeout=5) as response:
            assert response.status == 200 and response.read()
    finally:
        server.terminate()
        server.wait(timeout=30)
