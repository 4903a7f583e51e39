"""Running cases through an adapter and judging the answers (spec §16.3–16.5)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Iterable

from haptify_conform.adapters import Adapter, Answer
from haptify_conform.cases import REPO_ROOT, Case, fixture_path
from haptify_conform.judge import Verdict, case_fields, judge_acceptance, judge_metric, judge_rejection


def load_skips(path: Path | None) -> dict[str, str]:
    """The implementation's skip list: ``{"skips": {"case-id": "reason", …}}`` (spec §16.5)."""
    if path is None:
        return {}
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    skips = data.get("skips") if isinstance(data, dict) else None
    if not isinstance(skips, dict) or not all(isinstance(v, str) and v for v in skips.values()):
        raise ValueError(f'{path}: expected {{"skips": {{case id: reason}}}}')
    return skips


def judge(case: Case, answer: Answer) -> Verdict:
    """Turn an implementation's answer into a verdict for ``case`` (spec §16.3)."""
    base = case_fields(case)
    if answer.kind == "error":
        verdict = Verdict(status="error", message=answer.message, **base)
    elif answer.kind == "skipped":
        verdict = Verdict(status="skipped", message=f"implementation skipped it: {answer.message}", **base)
    elif answer.kind == "rejected":
        verdict = judge_rejection(case, answer.payload)
    elif case.metric == "validate":
        verdict = judge_acceptance(case, answer.payload)
    else:
        verdict = judge_metric(case, answer.payload)
    verdict.duration_s = answer.duration_s
    return verdict


def run_cases(
    cases: Iterable[Case],
    adapter: Adapter,
    skips: dict[str, str] | None = None,
    on_verdict: Callable[[Verdict], None] | None = None,
    repo: Path = REPO_ROOT,
) -> list[Verdict]:
    """Run every case (skip-listed ones are reported as skipped, never silently dropped; spec §16.5).

    Fixtures are looked up under ``repo/fixtures``.
    """
    skips = skips or {}
    verdicts = []
    try:
        for case in cases:
            if case.id in skips:
                v = Verdict(
                    case_id=case.id,
                    metric=case.metric,
                    status="skipped",
                    spec_section=case.spec_section,
                    level=case.level,
                    message=f"skip list: {skips[case.id]}",
                )
            else:
                session = fixture_path(case, repo)
                if not session.exists():
                    v = Verdict(
                        case_id=case.id,
                        metric=case.metric,
                        status="error",
                        spec_section=case.spec_section,
                        level=case.level,
                        message=f"fixture {case.fixture} is missing from the suite",
                    )
                else:
                    v = judge(case, adapter.run(case, session))
            verdicts.append(v)
            if on_verdict:
                on_verdict(v)
    finally:
        adapter.close()
    return verdicts
