"""What one conformance challenge costs (spec §17.8): the registry issuing it (generating one known-answer
session per metric family from a fresh secret seed, packing them, recording the cases), the reference
answering every case, and the registry judging and recording the answer.

``challenge.issue`` / ``challenge.answer`` are called directly (no HTTP) on a fresh SQLite registry; the
reference runs in this process (``haptify.conform_adapter.analyse``, its per-session context cache as in
``--python`` mode). Three challenges (three seeds): each phase's median and max. No target: the figure says
how long a lab's ``haptify-conform --challenge`` takes and keeps the challenge within test budgets.
"""

from __future__ import annotations

import statistics
import sys
import tarfile
import tempfile
import time
from pathlib import Path

from haptify.conform_adapter import IMPLEMENTATION, analyse
from haptify_tools.registry import challenge
from haptify_tools.registry.service import Caller, Registry, Settings

CHALLENGES = 3


def one(reg: Registry, caller: Caller, work: Path) -> tuple[float, float, float, int]:
    """Seconds to issue, to answer with the reference, to judge; and the number of cases."""
    t0 = time.perf_counter()
    issued = challenge.issue(reg, caller)
    t1 = time.perf_counter()
    with tarfile.open(challenge.sessions_archive(reg, issued["id"]), "r:gz") as tar:
        tar.extractall(work / issued["id"], filter="data")
    answers = {c["id"]: analyse(str(work / issued["id"] / c["session"]), c["metric"], c["parameters"])
               for c in issued["cases"]}
    t2 = time.perf_counter()
    judged = challenge.answer(reg, issued["id"], caller, challenge.Answers(implementation=IMPLEMENTATION, answers=answers))
    t3 = time.perf_counter()
    if judged["state"] != "passed":
        raise SystemExit(f"the reference failed challenge {issued['id']}: "
                         f"{[c for c in judged['result']['cases'] if c['status'] != 'passed']}")
    return t1 - t0, t2 - t1, t3 - t2, len(issued["cases"])


def main() -> int:
    with tempfile.TemporaryDirectory(prefix="bench-registry-challenge-") as tmp:
        root = Path(tmp)
        reg = Registry(Settings(data_dir=root / "data"), lock=False)
        try:
            reg.create_token("lab-bench")
            caller = Caller(1, "lab-bench", "submit")
            runs = [one(reg, caller, root) for _ in range(CHALLENGES)]
        finally:
            reg.close()
    for name, k in (("issue", 0), ("reference answers", 1), ("judge + record", 2)):
        xs = [r[k] for r in runs]
        print(f"{name}: median {statistics.median(xs):.2f} s, max {max(xs):.2f} s")
    total = [r[0] + r[1] + r[2] for r in runs]
    print(f"one challenge ({runs[0][3]} cases, {len(challenge.FAMILIES)} families): median {statistics.median(total):.2f} s, "
          f"max {max(total):.2f} s over {CHALLENGES}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
