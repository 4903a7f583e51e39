"""The registry's limits are part of its API (spec §17.4): ``GET /api/v1/limits`` says them, and
``haptify submit`` checks the archive's size against them before sending (E960 with a hint), so an
over-limit upload is never started."""

from __future__ import annotations

import logging

from fastapi.testclient import TestClient

from _registry_fixtures import base  # noqa: F401  (base: fixture)
from haptify.cli import UI
from haptify_tools.registry.app import create_app
from haptify_tools.registry.bundle import Limits
from haptify_tools.registry.live import serve_in_thread
from haptify_tools.registry.service import Settings
from test_registry_crash import _parse


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
    app = create_app(Settings(data_dir=tmp_path / "data", limits=Limits(max_archive_bytes=16 << 10)))  # raw: 34 KiB, without: 5 KiB
    token = app.state.registry.create_token("lab-a")
    try:
        with serve_in_thread(app) as url, caplog.at_level(logging.WARNING, logger="haptify.registry"):
            argv = ["submit", str(session), "--results", str(results), "--conformance", str(report),
                    "--registry", url, "--token", token]
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
