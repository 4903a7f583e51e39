"""How the runner talks to an implementation (spec §16.4): a command per case, a persistent JSON-lines
process, or an in-process Python function. Every adapter turns one case into an :class:`Answer`.
"""

from __future__ import annotations

import copy
import importlib
import json
import queue
import shlex
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import IO, Any, Callable, Protocol

from haptify_conform import PROTOCOL_VERSION


@dataclass
class Answer:
    """What the implementation said: ``results`` (accepted), ``findings`` (rejected), skipped, or an error.
    Spec §16.4."""

    kind: str  # "results" | "rejected" | "skipped" | "error"
    payload: Any = None
    message: str = ""
    duration_s: float = 0.0
    implementation: dict[str, Any] = field(default_factory=dict)


def note_implementation(adapter: Adapter, answer: Answer) -> Answer:
    """Remember the ``implementation`` a results document names, for the report header (spec §16.6)."""
    if not getattr(adapter, "implementation", None) and answer.kind == "results":
        named = answer.payload.get("implementation") if isinstance(answer.payload, dict) else None
        if isinstance(named, dict) and named.get("name") and named.get("version"):
            adapter.implementation = {"name": str(named["name"]), "version": str(named["version"])}
    return answer


def classify(document: Any) -> Answer:
    """Read an implementation's output document: a results.json, or a findings report.
    Any other document is an error of the implementation, spec §16.4.1."""
    if not isinstance(document, dict):
        return Answer("error", message=f"output is not a JSON object but {type(document).__name__}")
    not_lists = [
        k for k in ("metrics", "unavailable", "warnings", "findings") if k in document and not isinstance(document[k], list)
    ]
    if not_lists:  # judged as written, a malformed document would stop the runner or pass as an acceptance
        return Answer(
            "error", message=f"output field(s) {', '.join(map(repr, not_lists))} must be JSON arrays (spec §15.1, §16.4.1)"
        )
    if "metrics" in document:
        return Answer("results", document)
    if "findings" in document:
        findings = document["findings"]
        errors = [f for f in findings if isinstance(f, dict) and f.get("severity", "error") == "error"]
        # a rejection keeps its warnings too: a negative case may expect them beside the errors (spec §16.3)
        return Answer("rejected", findings) if errors else Answer("results", {"metrics": [], "findings": findings})
    return Answer("error", message="output has neither 'metrics' (results) nor 'findings' (rejection)")


class CannotStart(RuntimeError):
    """The implementation's program cannot be started at all (spec §16.6: exit 2, not a failed case)."""


class CaseRequest(Protocol):
    """What an adapter sends of a case (spec §16.4): a suite's :class:`Case` or a registry's challenge task."""

    @property
    def id(self) -> str: ...

    @property
    def metric(self) -> str: ...

    @property
    def parameters(self) -> dict[str, Any]: ...


class Adapter(Protocol):
    """What the runner needs of an adapter (spec §16.4): its name, the implementation it found, one
    :class:`Answer` per case, and a close."""

    name: str
    implementation: dict[str, Any]

    def run(self, case: CaseRequest, session: Path) -> Answer: ...

    def close(self) -> None: ...


EXIT_NOT_EXECUTABLE, EXIT_NOT_FOUND = 126, 127  # a shell's "cannot execute" and "command not found"


class CmdAdapter:
    """``--cmd "PROGRAM {session} {out}"``: one process per case (substituted: {session} {out} {metric} {case} {params}),
    cases that give the same command line sharing one run. Spec §16.4.1."""

    name = "cmd"

    def __init__(self, template: str, timeout_s: float) -> None:
        self.implementation: dict[str, Any] = {}
        self.argv = shlex.split(template)
        if not any("{session}" in a for a in self.argv) or not any("{out}" in a for a in self.argv):
            raise ValueError("the --cmd template must contain {session} and {out}")
        self.timeout_s = timeout_s
        self.answered = False  # has the program run once (then a later 126/127 is that case's error)
        self._uses = {key: any(key in a for a in self.argv) for key in ("{metric}", "{case}", "{params}")}
        self._answers: dict[tuple[str, ...], Answer] = {}  # by command line (:meth:`_command_line`)

    def _command_line(self, case: CaseRequest, session: Path) -> tuple[str, ...]:
        """What the program would be told for ``case``, but for the output file's name: the session, and the
        case's metric, id and parameters where the template passes them (spec §16.4.1)."""
        return (
            str(session),
            case.metric if self._uses["{metric}"] else "",
            case.id if self._uses["{case}"] else "",
            json.dumps(case.parameters, sort_keys=True) if self._uses["{params}"] else "",
        )

    def run(self, case: CaseRequest, session: Path) -> Answer:
        """The program's answer for ``case``: from a run of its own, or from the earlier run of the same command
        line (a copy, with no time of its own: ``duration_s`` 0)."""
        line = self._command_line(case, session)
        if line in self._answers:
            return replace(copy.deepcopy(self._answers[line]), duration_s=0.0)
        answer = self._run(case, session)
        self._answers[line] = copy.deepcopy(answer)
        return answer

    def _run(self, case: CaseRequest, session: Path) -> Answer:
        with tempfile.TemporaryDirectory(prefix="haptify-conform-") as tmp:
            out = Path(tmp) / "out.json"
            params = Path(tmp) / "params.json"
            params.write_text(json.dumps(case.parameters))
            subst = {
                "{session}": str(session),
                "{out}": str(out),
                "{metric}": case.metric,
                "{case}": case.id,
                "{params}": str(params),
            }
            argv = []
            for a in self.argv:
                for k, v in subst.items():
                    a = a.replace(k, v)
                argv.append(a)
            start = time.perf_counter()
            try:
                proc = subprocess.run(argv, capture_output=True, text=True, timeout=self.timeout_s, stdin=subprocess.DEVNULL)
            except subprocess.TimeoutExpired:
                return Answer("error", message=f"timed out after {self.timeout_s} s", duration_s=self.timeout_s)
            except OSError as exc:
                raise CannotStart(f"cannot start {argv[0]!r}: {exc.strerror}") from None
            elapsed = time.perf_counter() - start
            if not out.exists() and proc.returncode in (EXIT_NOT_EXECUTABLE, EXIT_NOT_FOUND) and not self.answered:
                raise CannotStart(
                    f"{argv[0]!r} exited {proc.returncode} without output on the first case; "
                    f"its stderr:\n{proc.stderr.strip()[-2000:]}"
                )
            self.answered = True
            if not out.exists():
                tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
                return Answer("error", message=f"exit {proc.returncode}, wrote no output; {' / '.join(tail)}", duration_s=elapsed)
            try:
                answer = classify(json.loads(out.read_text(encoding="utf-8")))
            except (json.JSONDecodeError, UnicodeDecodeError) as exc:
                return Answer("error", message=f"output is not JSON: {exc}", duration_s=elapsed)
            answer.duration_s = elapsed
            return note_implementation(self, answer)

    def close(self) -> None:
        pass


class JsonlAdapter:
    """``--jsonl "PROGRAM"``: one persistent process speaking the JSON-lines protocol (spec §16.4.2)."""

    name = "jsonl"

    def __init__(self, command: str, timeout_s: float, max_restarts: int = 3) -> None:
        self.argv = shlex.split(command)
        self.timeout_s = timeout_s
        self.max_restarts = max_restarts
        self.starts = 0
        self.seq = 0
        self.proc: subprocess.Popen[str] | None = None
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.implementation: dict[str, Any] = {}

    @property
    def restarts(self) -> int:
        """How often the process was started again after the first start."""
        return max(0, self.starts - 1)

    # -- process management ---------------------------------------------------------------------
    def _start(self) -> None:
        self.proc = subprocess.Popen(
            self.argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, bufsize=1
        )
        self.lines = queue.Queue()
        threading.Thread(target=self._pump, args=(self.proc, self.lines), daemon=True).start()
        hello = self.request({"op": "hello", "protocol": PROTOCOL_VERSION})
        if hello.get("status") != "ok" or hello.get("protocol") != PROTOCOL_VERSION:
            raise RuntimeError(f"handshake failed: {hello}")
        self.implementation = hello.get("implementation", {})

    @staticmethod
    def _pump(proc: subprocess.Popen[str], lines: queue.Queue[str | None]) -> None:
        assert proc.stdout is not None  # opened with stdout=PIPE in _start
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    def _kill(self) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)
        self.proc = None

    def request(self, message: dict[str, Any]) -> dict[str, Any]:
        """Send one request and wait for the reply with the same ``seq`` (raises TimeoutError / RuntimeError)."""
        self.seq += 1
        message = {"seq": self.seq, **message}
        assert self.proc is not None and self.proc.stdin is not None
        try:
            self.proc.stdin.write(json.dumps(message) + "\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            raise RuntimeError(f"implementation closed its input: {exc}") from None
        deadline = time.monotonic() + self.timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no reply within {self.timeout_s} s")
            try:
                line = self.lines.get(timeout=remaining)
            except queue.Empty:
                raise TimeoutError(f"no reply within {self.timeout_s} s") from None
            if line is None:
                raise RuntimeError("implementation exited")
            try:
                reply = json.loads(line)
            except json.JSONDecodeError:
                raise RuntimeError(f"reply is not JSON: {line[:200]!r}") from None
            if not isinstance(reply, dict) or reply.get("seq") != self.seq:
                raise RuntimeError(f"reply out of sequence: expected seq {self.seq}, got {line[:200]!r}")
            return reply

    # -- cases ----------------------------------------------------------------------------------
    def run(self, case: CaseRequest, session: Path) -> Answer:
        if self.proc is None or self.proc.poll() is not None:
            if self.starts > self.max_restarts:
                return Answer("error", message=f"implementation failed more than {self.max_restarts} restarts; not restarted")
            self.starts += 1
            try:
                self._start()
            except (RuntimeError, TimeoutError, OSError) as exc:
                self._kill()
                if self.starts == 1:  # it never answered: nothing it would be judged on exists (spec §16.6)
                    raise CannotStart(f"cannot start {self.argv[0]!r}: {getattr(exc, 'strerror', None) or exc}") from None
                return Answer("error", message=f"cannot start the implementation: {exc}")
        start = time.perf_counter()
        try:
            reply = self.request(
                {"op": "run", "case": case.id, "session": str(session), "metric": case.metric, "parameters": case.parameters}
            )
        except (TimeoutError, RuntimeError) as exc:
            self._kill()  # crash isolation: the next case gets a fresh process
            return Answer("error", message=str(exc), duration_s=time.perf_counter() - start)
        elapsed = time.perf_counter() - start
        status = reply.get("status")
        if status == "ok":
            answer = classify(reply.get("results"))
        elif status == "error":
            answer = Answer("rejected", reply.get("findings") or [], message=str(reply.get("message", "")))
        elif status == "skipped":
            answer = Answer("skipped", message=str(reply.get("reason", "")))
        else:
            answer = Answer("error", message=f"unknown reply status {status!r}")
        answer.duration_s = elapsed
        return answer

    def close(self) -> None:
        if self.proc and self.proc.poll() is None:
            try:
                self.request({"op": "bye"})
            except (TimeoutError, RuntimeError):
                pass
            try:
                assert self.proc.stdin is not None  # opened with stdin=PIPE in _start
                self.proc.stdin.close()
                self.proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                self._kill()


class PythonAdapter:
    """``--python module:function``: ``function(session, metric, parameters) -> dict`` called in-process.
    Spec §16.4.3."""

    name = "python"

    def __init__(self, target: str) -> None:
        module, _, func = target.partition(":")
        if not module or not func:
            raise ValueError("--python takes module:function")
        self.func: Callable[[str, str, dict[str, Any]], Any] = getattr(importlib.import_module(module), func)
        self.implementation: dict[str, Any] = {}

    def run(self, case: CaseRequest, session: Path) -> Answer:
        start = time.perf_counter()
        try:
            document = self.func(str(session), case.metric, dict(case.parameters))
        except Exception as exc:  # crash isolation for in-process implementations
            return Answer("error", message=f"{type(exc).__name__}: {exc}", duration_s=time.perf_counter() - start)
        answer = classify(document)
        answer.duration_s = time.perf_counter() - start
        return note_implementation(self, answer)

    def close(self) -> None:
        pass


def serve_jsonl(
    analyse: Callable[[str, str, dict[str, Any]], dict[str, Any]],
    implementation: dict[str, Any],
    stdin: IO[str] | None = None,
    stdout: IO[str] | None = None,
) -> int:
    """Serve the JSON-lines protocol for a Python ``analyse`` function (used by the reference server).
    Protocol 1 of spec §16.4.2."""
    import sys

    stdin = stdin or sys.stdin
    stdout = stdout or sys.stdout

    def reply(obj: dict[str, Any]) -> None:
        stdout.write(json.dumps(obj, default=str) + "\n")
        stdout.flush()

    for line in stdin:
        try:
            msg = json.loads(line)
            seq = msg["seq"]
            op = msg["op"]
        except (json.JSONDecodeError, KeyError, TypeError):
            reply({"seq": None, "status": "error", "message": "malformed request", "findings": []})
            continue
        if op == "hello":
            reply({"seq": seq, "status": "ok", "protocol": PROTOCOL_VERSION, "implementation": implementation})
        elif op == "bye":
            reply({"seq": seq, "status": "ok"})
            return 0
        elif op == "run":
            document = analyse(msg.get("session", ""), msg.get("metric", ""), msg.get("parameters") or {})
            answer = classify(document)
            if answer.kind == "rejected":
                reply({"seq": seq, "status": "error", "findings": answer.payload})
            else:
                reply({"seq": seq, "status": "ok", "results": document})
        else:
            reply({"seq": seq, "status": "error", "message": f"unknown op {op!r}", "findings": []})
    return 0
