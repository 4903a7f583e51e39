"""A live registry (uvicorn on 127.0.0.1) killed in the middle of submissions (spec §17.7): after a
restart every acknowledged submission is there with its archive, nothing half-stored is, and no
temporary or orphan file is left. Also the ``haptify submit`` and ``haptify registry`` commands end to end."""

from __future__ import annotations

import json
import os
import signal
import socket
import threading
import time
import urllib.request
from pathlib import Path

import pytest
from _registry_fixtures import SERVE, base, bundle_for, free_port, pg_server, start, variant, wait_http  # noqa: F401  (base: fixture)

from haptify.cli.main import UI
from haptify.errors import HaptifyError
from haptify_tools.registry import cmd_registry, cmd_submit
from haptify_tools.registry.records import Settings
from haptify_tools.registry.service import Registry


def _parse(argv: list[str]):
    import argparse

    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers()
    cmd_submit.register(sub)
    cmd_registry.register(sub)
    return parser.parse_args(argv)


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request):
    """None (SQLite in the data folder) or a fresh database on a throwaway PostgreSQL server."""
    if request.param == "sqlite":
        return None
    return request.getfixturevalue("pg_server").new_database(f"k{abs(hash(request.node.nodeid)) % 10**9}")


def test_killed_mid_submission_loses_nothing_accepted_and_leaves_nothing_half(base, tmp_path, db_url):
    report = base[3]
    data = tmp_path / "data"
    registry = Registry(Settings(data_dir=data, db_url=db_url), lock=False)
    token = registry.create_token("lab-a")
    registry.close()
    archives = []
    for i in range(12):
        s, r = variant(base, tmp_path, f"k{i}", rms=[1.0 + i, 2.0])
        archives.append(bundle_for(s, r, report, tmp_path / f"k{i}.tar.gz")[0])
    proc, port = start(data, db_url)
    acknowledged: list[str] = []
    lock = threading.Lock()

    def worker(mine: list[Path]) -> None:
        for archive in mine:
            try:
                outcome = cmd_submit.post_bundle(f"http://127.0.0.1:{port}", token, archive)
            except Exception:
                return  # the server died: this submission was never acknowledged
            with lock:
                acknowledged.append(outcome["id"])

    threads = [threading.Thread(target=worker, args=(archives[i::4],)) for i in range(4)]
    for t in threads:
        t.start()
    deadline = time.monotonic() + 30
    while len(acknowledged) < 4 and time.monotonic() < deadline:
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)  # in the middle of the remaining submissions
    proc.wait()
    for t in threads:
        t.join()
    assert 4 <= len(acknowledged) < 12, "the kill should land while submissions are in flight"
    proc, port = start(data, db_url)  # restart: migrations, then the sweep
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/v1/health") as r:
            health = json.loads(r.read())
        assert health["swept"]["missing"] == 0
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/v1/submissions?limit=1000") as r:
            stored = {s["id"] for s in json.loads(r.read())}
        assert set(acknowledged) <= stored  # nothing acknowledged is lost
        files = sorted(p.name for p in (data / "bundles").rglob("*") if p.is_file())
        assert len(files) == len(stored)  # one archive per record: no orphan, no record without archive
        assert list((data / "tmp").iterdir()) == []
        # the submissions that were cut off can simply be sent again
        for archive in archives:
            cmd_submit.post_bundle(f"http://127.0.0.1:{port}", token, archive)
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/v1/submissions?limit=1000") as r:
            assert len(json.loads(r.read())) == 12
    finally:
        proc.terminate()
        proc.wait()


def test_orphans_are_swept_at_start_up(tmp_path):
    data = tmp_path / "data"
    Registry(Settings(data_dir=data), lock=False).close()
    (data / "tmp").mkdir(parents=True, exist_ok=True)
    (data / "tmp" / "upload-dead.tar.gz").write_bytes(b"half")
    (data / "tmp" / "unpack-dead").mkdir()
    orphan = data / "bundles" / "ab" / ("ab" + "0" * 62 + ".tar.gz")
    orphan.parent.mkdir(parents=True)
    orphan.write_bytes(b"renamed but never committed")
    registry = Registry(Settings(data_dir=data))
    try:
        assert registry.sweep() == {"tmp": 2, "orphans": 1, "missing": 0}
        assert not orphan.exists() and list((data / "tmp").iterdir()) == []
    finally:
        registry.close()


def test_one_process_per_data_folder(tmp_path):
    first = Registry(Settings(data_dir=tmp_path / "d"))
    try:
        with pytest.raises(HaptifyError) as e:
            Registry(Settings(data_dir=tmp_path / "d"))
        assert e.value.findings[0].code == "E978"
    finally:
        first.close()


def test_submit_and_registry_commands_end_to_end(base, tmp_path, capsys):
    root, session, results, report, impl = base
    data = tmp_path / "data"
    args = _parse(["registry", "token", "create", "--lab", "lab-a", "--data", str(data)])
    assert args.func(args, UI()) == 0
    token = capsys.readouterr().out.strip()
    assert token.startswith("hpt_")
    stored = (data / "registry.sqlite3").read_bytes()
    assert token.encode() not in stored  # only the hash is stored
    args = _parse(["submit", str(session), "--results", str(results), "--conformance", str(report), "--dry-run"])
    assert args.func(args, UI()) == 0
    assert "would-accept" in capsys.readouterr().out
    proc, port = start(data)
    try:
        url = f"http://127.0.0.1:{port}"
        args = _parse(
            [
                "submit",
                str(session),
                "--results",
                str(results),
                "--conformance",
                str(report),
                "--registry",
                url,
                "--token",
                token,
                "--dry-run",
            ]
        )
        assert args.func(args, UI()) == 0
        assert "the registry says:" in capsys.readouterr().out
        args = _parse(
            ["submit", str(session), "--results", str(results), "--conformance", str(report), "--registry", url, "--token", token]
        )
        assert args.func(args, UI()) == 0
        out = capsys.readouterr().out
        assert out.startswith("accepted: submission ")
        args = _parse(["submit", str(session), "--results", str(results), "--registry", url, "--token", "hpt_wrong"])
        assert args.func(args, UI()) == 1  # refused: the findings go to stderr
        assert "E970" in capsys.readouterr().err
        args = _parse(
            ["submit", str(session), "--results", str(results), "--registry", f"http://127.0.0.1:{free_port()}", "--token", token]
        )
        with pytest.raises(HaptifyError) as e:  # nobody listens there: a wrong URL, not "retry later" (exit 2)
            args.func(args, UI())
        assert e.value.findings[0].code == "E903" and "check the URL" in e.value.findings[0].message
    finally:
        proc.terminate()
        proc.wait()


@pytest.mark.parametrize(
    "registry, reason, code",
    [
        ("http://regsitry.example.org", socket.gaierror(-2, "Name or service not known"), "E903"),  # a typo in the host
        ("registry.example.org", OSError("unknown url type"), "E903"),  # no scheme: no host
        ("http://127.0.0.1:9", ConnectionRefusedError(111, "Connection refused"), "E903"),  # nothing listens
        ("http://registry.example.org", TimeoutError("timed out"), "E978"),  # may pass: retry
    ],
)
def test_an_unreachable_registry_says_whether_to_check_the_url_or_retry(registry, reason, code):
    from haptify_tools.registry.cmd_submit import unreachable

    finding = unreachable(registry, registry + "/api/v1/submissions", reason).findings[0]
    assert finding.code == code
    assert ("check the URL" in finding.message) == (code == "E903")
