"""The registry's limits are part of its API (spec §17.4): ``GET /api/v1/limits`` says them, and
``haptify submit`` checks the archive's size against them before sending (E960 with a hint), so an
over-limit upload is never started."""

from __future__ import annotations

import logging
import socket
import time

from _registry_fixtures import base, bundle_for  # noqa: F401  (base: fixture)
from fastapi.testclient import TestClient
from test_registry_crash import _parse

from haptify.cli.main import UI
from haptify_tools.registry.app import create_app
from haptify_tools.registry.bundle import Limits
from haptify_tools.registry.live import serve_in_thread
from haptify_tools.registry.records import Settings


def test_the_limits_are_advertised(tmp_path):
    limits = Limits(max_archive_bytes=12345, worker_seconds=7.0)
    app = create_app(Settings(data_dir=tmp_path / "data", limits=limits, challenge_ttl_s=60.0))
    with TestClient(app) as client:
        said = client.get("/api/v1/limits").json()
    app.state.registry.close()
    assert said["max_archive_bytes"] == 12345 and said["worker_seconds"] == 7.0 and said["challenge_ttl_s"] == 60.0
    assert said["max_unpacked_bytes"] == Limits().max_unpacked_bytes


def test_an_over_limit_bundle_is_refused_before_sending(base, tmp_path, capsys, caplog):
    root, session, results, report, impl = base
    app = create_app(
        Settings(data_dir=tmp_path / "data", limits=Limits(max_archive_bytes=16 << 10))
    )  # raw: 34 KiB, without: 5 KiB
    token = app.state.registry.create_token("lab-a")
    try:
        with serve_in_thread(app) as url, caplog.at_level(logging.WARNING, logger="haptify.registry"):
            argv = [
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
            ]
            args = _parse(argv + ["--include-raw"])
            assert args.func(args, UI()) == 1
            err = capsys.readouterr().err
            assert "E960" in err and "was not sent" in err and "--include-raw" in err  # the code's hint
            assert not [r for r in caplog.records if "POST /api/v1/submissions" in r.getMessage()]  # nothing reached it
            args = _parse(argv)  # without raw streams the bundle is small: it is sent and accepted
            assert args.func(args, UI()) == 0
            assert capsys.readouterr().out.startswith("accepted: submission ")
    finally:
        app.state.registry.close()


# --- resumable chunked upload (spec §17.5.2) ------------------------------------------------------------


def _raw_patch_cut_short(url: str, uid: str, token: str, offset: int, declared: int, data: bytes) -> None:
    """A PATCH whose connection drops after ``data``: Content-Length says ``declared`` bytes, fewer come."""
    host, port = url.removeprefix("http://").split(":")
    head = (
        f"PATCH /api/v1/uploads/{uid} HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {token}\r\n"
        f"Upload-Offset: {offset}\r\nContent-Type: application/offset+octet-stream\r\n"
        f"Content-Length: {declared}\r\nConnection: close\r\n\r\n"
    ).encode()
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(head + data)
        time.sleep(0.5)  # the server reads what arrived (bytes still in its buffer at the drop are lost to it)
    time.sleep(0.3)


def test_an_upload_cut_short_keeps_what_arrived_and_resumes(base, tmp_path):
    root, session, results, report, impl = base
    archive, digest = bundle_for(session, results, report, tmp_path / "raw.tar.gz", include_raw=True)
    data = archive.read_bytes()
    app = create_app(Settings(data_dir=tmp_path / "data", limits=Limits(max_archive_bytes=1 << 20)))
    token = app.state.registry.create_token("lab-a")
    h = {"Authorization": f"Bearer {token}"}
    try:
        with serve_in_thread(app) as url, TestClient(app) as client:
            assert (
                client.post("/api/v1/uploads", headers={**h, "Upload-Length": str(2 << 20)}).json()["findings"][0]["code"]
                == "E960"
            )
            up = client.post("/api/v1/uploads", headers={**h, "Upload-Length": str(len(data))}).json()
            assert up["offset"] == 0 and up["length"] == len(data)
            first = client.patch(f"/api/v1/uploads/{up['id']}", content=data[:10_000], headers={**h, "Upload-Offset": "0"})
            assert first.json()["offset"] == 10_000
            _raw_patch_cut_short(url, up["id"], token, 10_000, 20_000, data[10_000:17_000])  # the connection drops
            got = client.get(f"/api/v1/uploads/{up['id']}", headers=h).json()
            assert got["offset"] == 17_000 and not got["complete"]  # the 7 000 bytes that arrived are kept
            wrong = client.patch(f"/api/v1/uploads/{up['id']}", content=data[10_000:], headers={**h, "Upload-Offset": "10000"})
            assert wrong.status_code == 400 and wrong.json()["findings"][0]["expected"] == 17_000
            early = client.post(f"/api/v1/uploads/{up['id']}/submit", headers=h)
            assert early.status_code == 400 and early.json()["findings"][0]["code"] == "E975"
            rest = client.patch(f"/api/v1/uploads/{up['id']}", content=data[17_000:], headers={**h, "Upload-Offset": "17000"})
            assert rest.json()["complete"]
            done = client.post(f"/api/v1/uploads/{up['id']}/submit", headers=h)
            assert done.status_code == 201 and done.json()["digest"] == digest
            assert done.json()["verification"]["status"] == "verified"
            stored = client.get(f"/api/v1/submissions/{done.json()['id']}/bundle").content
            assert stored == data  # byte for byte
            assert client.get(f"/api/v1/uploads/{up['id']}", headers=h).status_code == 404  # the upload ended
    finally:
        app.state.registry.close()


def test_an_upload_survives_a_restart_of_the_registry(base, tmp_path):
    """Start an upload, stop the registry, start a new app on the same data folder: the upload is there at
    its offset, continues, completes and is verified; a torn chunk (bytes past the recorded offset) is cut."""
    root, session, results, report, impl = base
    archive, digest = bundle_for(session, results, report, tmp_path / "raw.tar.gz", include_raw=True)
    data = archive.read_bytes()
    settings = Settings(data_dir=tmp_path / "data")
    first = create_app(settings)
    token = first.state.registry.create_token("lab-a")
    h = {"Authorization": f"Bearer {token}"}
    try:
        with TestClient(first) as client:
            up = client.post("/api/v1/uploads", headers={**h, "Upload-Length": str(len(data))}).json()
            assert (
                client.patch(f"/api/v1/uploads/{up['id']}", content=data[:12_345], headers={**h, "Upload-Offset": "0"}).json()[
                    "offset"
                ]
                == 12_345
            )
    finally:
        first.state.registry.close()
    part = tmp_path / "data" / "uploads" / f"{up['id']}.part"
    with open(part, "ab") as fh:  # a chunk the crash tore: written, never acknowledged
        fh.write(b"\x00" * 999)
    second = create_app(settings)
    try:
        assert second.state.swept["uploads_resumed"] == 1
        with TestClient(second) as client:
            got = client.get(f"/api/v1/uploads/{up['id']}", headers=h).json()
            assert got["offset"] == 12_345 and not got["complete"] and part.stat().st_size == 12_345
            rest = client.patch(f"/api/v1/uploads/{up['id']}", content=data[12_345:], headers={**h, "Upload-Offset": "12345"})
            assert rest.json()["complete"]
            done = client.post(f"/api/v1/uploads/{up['id']}/submit", headers=h)
            assert done.status_code == 201 and done.json()["digest"] == digest
            assert done.json()["verification"]["status"] == "verified"
            assert client.get(f"/api/v1/submissions/{done.json()['id']}/bundle").content == data
        assert sorted(p.name for p in (tmp_path / "data" / "uploads").iterdir()) == []
    finally:
        second.state.registry.close()


def test_stale_uploads_expire_and_are_deleted(tmp_path):
    """An upload without a chunk for upload_ttl_s is gone: at start-up, and in a running registry."""
    settings = Settings(data_dir=tmp_path / "data", upload_ttl_s=0.5)
    folder = tmp_path / "data" / "uploads"
    app = create_app(settings)
    token = app.state.registry.create_token("lab-a")
    h = {"Authorization": f"Bearer {token}"}
    try:
        with TestClient(app) as client:
            assert client.get("/api/v1/limits").json()["upload_ttl_s"] == 0.5
            a = client.post("/api/v1/uploads", headers={**h, "Upload-Length": "100"}).json()
            assert (
                client.patch(f"/api/v1/uploads/{a['id']}", content=b"x" * 10, headers={**h, "Upload-Offset": "0"}).status_code
                == 200
            )
            time.sleep(0.8)
            assert client.get(f"/api/v1/uploads/{a['id']}", headers=h).json()["findings"][0]["code"] == "E973"
            assert not list(folder.iterdir())
            b = client.post("/api/v1/uploads", headers={**h, "Upload-Length": "100"}).json()
            assert client.get("/api/v1/uploads/..%2Fregistry", headers=h).status_code == 404  # ids name no other file
    finally:
        app.state.registry.close()
    assert sorted(p.name for p in folder.iterdir()) == [f"{b['id']}.json", f"{b['id']}.part"]
    time.sleep(0.8)
    again = create_app(settings)
    try:
        assert again.state.swept["uploads_expired"] == 1 and again.state.swept["uploads_resumed"] == 0
        assert not list(folder.iterdir())
    finally:
        again.state.registry.close()


def test_haptify_submit_resumes_after_a_dropped_chunk(base, tmp_path, capsys, monkeypatch):
    from haptify_tools.registry import cmd_submit

    root, session, results, report, impl = base
    app = create_app(Settings(data_dir=tmp_path / "data"))
    token = app.state.registry.create_token("lab-a")
    real = cmd_submit.request_json
    seen = {"patches": 0, "dropped": 0}

    def flaky(method, url, token, data=None, headers=None, *, registry):
        """The second chunk's connection drops after half of it arrived."""
        if method == "PATCH":
            seen["patches"] += 1
            if seen["patches"] == 2:
                seen["dropped"] += 1
                real(method, url, token, data[: len(data) // 2], headers, registry=registry)
                raise cmd_submit.fail("E978", "connection reset by peer (simulated)")
        return real(method, url, token, data, headers, registry=registry)

    monkeypatch.setattr(cmd_submit, "request_json", flaky)
    try:
        with serve_in_thread(app) as url:
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
                    "--include-raw",
                    "--chunk-mib",
                    str(8 / 1024),
                ]
            )
            assert args.func(args, UI()) == 0
            out = capsys.readouterr().out
            assert out.startswith("accepted: submission ") and "verification: verified" in out
            assert seen["dropped"] == 1 and seen["patches"] > 4  # 34 KiB in 8 KiB chunks, one resumed mid-chunk
    finally:
        app.state.registry.close()
