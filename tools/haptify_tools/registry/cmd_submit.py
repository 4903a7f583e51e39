"""``haptify submit SESSION --results results.json [--conformance report.json] [--include-raw] --registry URL
--token TOKEN [--supersedes ID] [--dry-run] [--keep FILE]`` (spec §17.2, §17.5).

Packs the submission bundle and uploads it. ``--dry-run`` runs the registry's own checks locally (limits,
documents, consistency, conformance, and with ``--include-raw`` the re-computation) and prints what the
registry would say; with ``--registry`` it also asks the registry (``?dry_run=true``), which adds the
checks only the registry can make: the token, the lab, a conformance report on file, supersession.
The token may come from the environment variable ``HAPTIFY_REGISTRY_TOKEN`` instead of the command line.

Exit codes: 0 accepted (or would be), also as a duplicate; 1 refused (the findings are printed) or a
metric disagrees with the registry's re-computation; 2 the command could not run (usage, registry
unreachable: E903, E978).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import sys
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify.formats.bundle_format import submission_id
from haptify.pipeline.gate import require_valid_session
from haptify_tools.registry.bundle import build_bundle, pack, unpack
from haptify_tools.registry.checks import check_bundle, verify_bundle

TOKEN_ENV = "HAPTIFY_REGISTRY_TOKEN"
TIMEOUT_S = 300
CHUNK_BYTES = 8 << 20  # archives larger than this go as a resumable upload, in chunks of this size
RESUME_ATTEMPTS = 5


def register(sub) -> None:
    """Add the ``submit`` sub-command: pack the bundle (spec §17.2), check it, upload it (§17.3)."""
    p = sub.add_parser("submit", help="pack a submission bundle and upload it to a results registry")
    p.add_argument("session", type=Path, help="the session folder the results were computed from")
    p.add_argument("--results", type=Path, required=True, help="results.json of the session")
    p.add_argument("--conformance", type=Path, help="haptify-conform --json-report of the implementation")
    p.add_argument("--include-raw", action="store_true", help="include the stream files (the registry re-computes and verifies)")
    p.add_argument("--supersedes", help="id of this lab's earlier submission that this one corrects")
    p.add_argument("--registry", help="registry base URL, e.g. http://127.0.0.1:8080")
    p.add_argument("--token", help=f"API token (default: ${TOKEN_ENV})")
    p.add_argument("--dry-run", action="store_true", help="check locally (and at the registry, if given); store nothing")
    p.add_argument("--keep", type=Path, help="also write the bundle archive to this file")
    p.add_argument(
        "--chunk-mib",
        type=float,
        default=CHUNK_BYTES / 2**20,
        help="archives larger than this many MiB are sent as a resumable upload in chunks of this size",
    )
    p.set_defaults(func=run)


def request_json(
    method: str, url: str, token: str, data: bytes | None = None, headers: dict | None = None, *, registry: str
) -> dict:
    """One request to the registry; its JSON answer. A refusal becomes a HaptifyError with the registry's
    findings; an unreachable registry E903/E978 (:func:`unreachable`). Spec §17.5.1."""
    request = urllib.request.Request(
        url, data=data, method=method, headers={"Authorization": f"Bearer {token}", **(headers or {})}
    )
    try:
        with urllib.request.urlopen(request, timeout=TIMEOUT_S) as response:
            return json.loads(response.read().decode("utf-8"))
    except urllib.error.HTTPError as exc:
        body = exc.read().decode("utf-8", "replace")
        try:
            findings = json.loads(body)["findings"]
            raise HaptifyError(
                *[
                    Finding(
                        f["code"],
                        f["message"],
                        file=f.get("file"),
                        pointer=f.get("pointer"),
                        expected=f.get("expected"),
                        found=f.get("found"),
                    )
                    for f in findings
                ]
            ) from None
        except (ValueError, KeyError, TypeError):
            raise fail(Code.REGISTRY_UNAVAILABLE, f"the registry answered HTTP {exc.code}: {body[:300]}", file=url) from None
    except (urllib.error.URLError, OSError) as exc:
        raise unreachable(registry, url, getattr(exc, "reason", exc)) from None


def post_bundle(registry: str, token: str, archive: Path, *, dry_run: bool = False) -> dict:
    """POST the archive to ``REGISTRY/api/v1/submissions`` in one request (spec §17.5.1)."""
    url = registry.rstrip("/") + "/api/v1/submissions" + ("?dry_run=true" if dry_run else "")
    return request_json("POST", url, token, archive.read_bytes(), {"Content-Type": "application/gzip"}, registry=registry)


def upload_resumable(
    registry: str,
    token: str,
    archive: Path,
    *,
    chunk_bytes: int = CHUNK_BYTES,
    dry_run: bool = False,
    attempts: int = RESUME_ATTEMPTS,
) -> dict:
    """Send the archive in chunks of ``chunk_bytes`` (spec §17.5.2) and submit it. When a chunk's connection
    drops, ask the registry how far it got and continue from there (at most ``attempts`` times in a row,
    waiting 0.2, 0.4, … s), so a broken connection costs at most one chunk; memory holds one chunk."""
    base = registry.rstrip("/") + "/api/v1/uploads"
    size = archive.stat().st_size
    state = request_json("POST", base, token, b"", {"Upload-Length": str(size)}, registry=registry)
    uid, offset, failures = state["id"], 0, 0
    with open(archive, "rb") as fh:
        while offset < size:
            fh.seek(offset)
            chunk = fh.read(chunk_bytes)
            try:
                offset = request_json(
                    "PATCH",
                    f"{base}/{uid}",
                    token,
                    chunk,
                    {"Upload-Offset": str(offset), "Content-Type": "application/offset+octet-stream"},
                    registry=registry,
                )["offset"]
                failures = 0
            except HaptifyError as err:
                if err.findings[0].code != Code.REGISTRY_UNAVAILABLE or failures >= attempts:
                    raise
                failures += 1
                time.sleep(0.1 * 2**failures)
                offset = request_json("GET", f"{base}/{uid}", token, registry=registry)["offset"]
    return request_json("POST", f"{base}/{uid}/submit" + ("?dry_run=true" if dry_run else ""), token, b"", registry=registry)


def send(registry: str, token: str, archive: Path, *, dry_run: bool = False, chunk_bytes: int = CHUNK_BYTES) -> dict:
    """Check the archive against the registry's limits (E960 before sending), then send it: in one request
    when it fits one chunk, else as a resumable upload."""
    check_size(archive, registry_limits(registry), registry)
    if archive.stat().st_size <= chunk_bytes:
        return post_bundle(registry, token, archive, dry_run=dry_run)
    return upload_resumable(registry, token, archive, chunk_bytes=chunk_bytes, dry_run=dry_run)


def registry_limits(registry: str) -> dict | None:
    """``GET REGISTRY/api/v1/limits`` (spec §17.4): what the registry accepts; None when it does not say."""
    url = registry.rstrip("/") + "/api/v1/limits"
    try:
        with urllib.request.urlopen(url, timeout=TIMEOUT_S) as response:
            return json.loads(response.read().decode("utf-8"))
    except urllib.error.HTTPError:
        return None  # an older registry: it still enforces its limits on the upload
    except (urllib.error.URLError, OSError) as exc:
        raise unreachable(registry, url, getattr(exc, "reason", exc)) from None


def check_size(archive: Path, limits: dict | None, registry: str) -> None:
    """E960 before anything is sent when the archive is larger than the registry's ``max_archive_bytes``."""
    if limits is None or "max_archive_bytes" not in limits:
        return
    size, limit = archive.stat().st_size, int(limits["max_archive_bytes"])
    if size > limit:
        raise fail(
            Code.BUNDLE_TOO_LARGE,
            f"the bundle is {size / 2**20:.1f} MiB; the registry at {registry} accepts at most "
            f"{limit / 2**20:.1f} MiB, so it was not sent",
            file=str(archive),
            expected=f"≤ {limit} bytes",
            found=f"{size} bytes",
        )


def unreachable(registry: str, url: str, reason: object) -> HaptifyError:
    """Why the registry could not be reached: a URL that names no host, or nothing listening there, is a
    wrong ``--registry`` (E903: check the URL); anything else may pass (E978: retry later). Spec §17.7."""
    if isinstance(reason, socket.gaierror) or not urllib.parse.urlsplit(registry).hostname:
        return fail(
            Code.USAGE,
            f"--registry {registry!r} names no host this machine can resolve ({reason}); check the URL",
            file=url,
            expected="http(s)://HOST[:PORT] of a Haptify registry",
            found=registry,
        )
    if isinstance(reason, ConnectionRefusedError):
        return fail(
            Code.USAGE,
            f"nothing answers at {registry!r} ({reason}); check the URL and port, or start the registry (haptify registry serve)",
            file=url,
            expected="the address of a running registry",
            found=registry,
        )
    return fail(Code.REGISTRY_UNAVAILABLE, f"cannot reach the registry at {registry}: {reason}", file=url)


def describe(outcome: dict) -> list[str]:
    """Human lines for a registry answer (or a local dry run)."""
    v = outcome["verification"]
    lines = [
        f"{outcome['status']}: submission {outcome['id']} (digest {outcome['digest']})",
        f"verification: {v['status']}" + (f" — {v['note']}" if v.get("note") else ""),
    ]
    for c in v.get("checks", []):
        if c["status"] != "agrees":
            lines.append(f"  {c['metric']}: {c['status']}{' (' + c['code'] + ')' if c.get('code') else ''} — {c['message']}")
    if outcome.get("supersedes"):
        lines.append(f"supersedes {outcome['supersedes']}")
    return lines


CANNOT_RUN = (Code.USAGE, Code.REGISTRY_UNAVAILABLE, Code.INTERNAL_ERROR)


def run(args, ui) -> int:
    """Pack, check and upload (or ``--dry-run``) one submission bundle; refusals are reported (spec §17.3)."""
    try:
        return _run(args, ui)
    except HaptifyError as err:
        if err.findings[0].code in CANNOT_RUN:
            raise
        if ui.json_mode:
            ui.emit_json({"status": "refused", "findings": [f.to_dict() for f in err.findings]})
        else:
            print("refused:", file=sys.stderr)
            for f in err.findings:
                print(str(f), file=sys.stderr)
        return 1


def _run(args, ui) -> int:
    token: str = args.token or os.environ.get(TOKEN_ENV, "")
    if not args.dry_run and not (args.registry and token):
        raise fail(
            Code.USAGE,
            "uploading needs --registry and --token (or $" + TOKEN_ENV + ")",
            expected="--registry URL --token TOKEN",
            found={"registry": args.registry, "token": bool(token)},
        )
    require_valid_session(args.session)  # an invalid session is never packed nor sent (spec §4.8)
    work = Path(tempfile.mkdtemp(prefix="haptify-submit-"))
    try:
        bundle, files = build_bundle(
            args.session, args.results, args.conformance, include_raw=args.include_raw, supersedes=args.supersedes
        )
        archive = work / "bundle.tar.gz"
        digest = pack(bundle, files, archive)
        if args.keep:
            shutil.copyfile(archive, args.keep)
        if args.dry_run:
            unpacked = unpack(archive, work / "unpacked")
            checked = check_bundle(unpacked)
            checked.verification = verify_bundle(checked, unpacked)
            outcome = {
                "id": submission_id(digest),
                "digest": digest,
                "status": "would-accept",
                "supersedes": args.supersedes,
                "verification": checked.verification.to_dict(),
                "checked": "locally",
            }
            lines = describe(outcome)
            if checked.conformance is None:
                lines.append(
                    "no conformance report included: the registry accepts it only with a passing report "
                    "of this implementation on file"
                )
            if args.registry and token:
                outcome = {
                    **send(args.registry, token, archive, dry_run=True, chunk_bytes=max(1, int(args.chunk_mib * 2**20))),
                    "checked": "locally and by the registry",
                }
                lines += ["the registry says:"] + describe(outcome)
        else:
            outcome = send(args.registry, token, archive, chunk_bytes=max(1, int(args.chunk_mib * 2**20)))
            lines = describe(outcome)
        if ui.json_mode:
            ui.emit_json(outcome)
        for line in lines:
            ui.say(line)
        return 0 if outcome["verification"]["status"] != "disagreeing" else 1
    finally:
        shutil.rmtree(work, ignore_errors=True)
