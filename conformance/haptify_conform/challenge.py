"""``haptify-conform --challenge URL --token T --cmd/--jsonl/--python …``: prove conformance to a results
registry (spec §17.8).

The client asks the registry for a fresh challenge (``POST /api/v1/challenges``), downloads its
sessions, runs the implementation on every case through the same adapters as the suite (spec §16.4),
and sends the outputs back (``POST /api/v1/challenges/{id}/answers``). The registry, which alone knows
the answers, judges them and records that this implementation and version passed or failed. Exit 0
passed, 1 failed, 2 the challenge could not be run (registry unreachable or refusing, implementation
that cannot start or does not name itself).
"""

from __future__ import annotations

import json
import tarfile
import tempfile
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from haptify_conform.adapters import Adapter, Answer

TIMEOUT_S = 300.0


class ChallengeError(RuntimeError):
    """The challenge could not be fetched, run or answered (exit 2)."""


@dataclass
class Task:
    """A challenge case as the adapters see it: id, metric and parameters (spec §16.4)."""

    id: str
    metric: str
    parameters: dict[str, Any] = field(default_factory=dict)


def _call(url: str, token: str, body: Any = None, *, raw: bool = False) -> Any:
    """GET (``body`` None) or POST JSON to the registry with the token; the JSON answer (bytes with ``raw``).
    A refusal raises :class:`ChallengeError` with the registry's codes and messages."""
    data = None if body is None else json.dumps(body).encode("utf-8")
    headers = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    if data is not None:
        headers["Content-Type"] = "application/json"
    method = "GET" if data is None else "POST"
    request = urllib.request.Request(url, data=data, headers=headers, method=method)
    try:
        with urllib.request.urlopen(request, timeout=TIMEOUT_S) as response:
            payload = response.read()
    except urllib.error.HTTPError as exc:
        try:
            findings = json.loads(exc.read()).get("findings", [])
            why = "; ".join(f"{f.get('code')} {f.get('message')}" for f in findings)
        except (ValueError, AttributeError):
            why = exc.reason
        raise ChallengeError(f"the registry refused {method} {url}: HTTP {exc.code}: {why}") from None
    except (urllib.error.URLError, OSError) as exc:
        raise ChallengeError(f"cannot reach the registry at {url}: {getattr(exc, 'reason', exc)}") from None
    return payload if raw else json.loads(payload)


def output_of(answer: Answer) -> dict[str, Any]:
    """What is sent for one case: the results document, the findings of a rejection, or ``{"error"}``."""
    if answer.kind == "results":
        results: dict[str, Any] = answer.payload  # classify() answers "results" for a JSON object only
        return results
    if answer.kind == "rejected":
        return {"findings": answer.payload}
    return {"error": f"{answer.kind}: {answer.message}"}


def run_challenge(registry: str, token: str, adapter: Adapter) -> dict[str, Any]:
    """Fetch a challenge from ``registry``, run ``adapter`` on each case and return the registry's judged
    record (spec §17.8). Raises :class:`ChallengeError` when it cannot be done."""
    base = registry.rstrip("/") + "/api/v1"
    issued = _call(f"{base}/challenges", token, {})
    archive = _call(f"{base}/challenges/{issued['id']}/sessions.tar.gz", token, raw=True)
    answers: dict[str, dict[str, Any]] = {}
    try:
        with tempfile.TemporaryDirectory(prefix="haptify-challenge-") as tmp:
            root = Path(tmp)
            (root / "sessions.tar.gz").write_bytes(archive)
            with tarfile.open(root / "sessions.tar.gz", "r:gz") as tar:
                tar.extractall(root / "sessions", filter="data")  # regular files at safe paths only
            for case in issued["cases"]:
                task = Task(case["id"], case["metric"], case.get("parameters", {}))
                answers[case["id"]] = output_of(adapter.run(task, root / "sessions" / case["session"]))
    finally:
        adapter.close()
    implementation = getattr(adapter, "implementation", None) or {}
    if not (implementation.get("name") and implementation.get("version")):
        raise ChallengeError(
            "the implementation did not name itself (name and version: the JSON-lines greeting or the "
            "results' 'implementation'), so the registry cannot record whose answer this is"
        )
    body = {"implementation": {"name": implementation["name"], "version": implementation["version"]}, "answers": answers}
    record: dict[str, Any] = _call(f"{base}/challenges/{issued['id']}/answers", token, body)
    return record


def _g(value: Any) -> str:
    """A number, or each number of a vector, to 6 significant digits."""
    return f"[{', '.join(_g(v) for v in value)}]" if isinstance(value, list) else f"{value:.6g}"


def summary(record: dict[str, Any]) -> str:
    """One line per case and a verdict line, for people."""
    result = record["result"]
    lines = [
        f"{'PASS' if c['status'] == 'passed' else 'FAIL'}  {c['case']}  expected {_g(c['expected'])}  found "
        f"{c['actual'] if c['actual'] is not None else '—'}{'  ' + c['message'] if c['message'] else ''}"
        for c in result["cases"]
    ]
    impl = result["implementation"]
    lines.append(
        f"challenge {record['id']}: {impl['name']} {impl['version']} "
        f"{'PASSED' if result['passed'] else 'FAILED'} ({sum(c['status'] == 'passed' for c in result['cases'])}"
        f"/{len(result['cases'])} cases)"
    )
    return "\n".join(lines)
