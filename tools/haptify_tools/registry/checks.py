"""What the registry checks in a bundle (spec §17.3), shared by the service and ``haptify submit --dry-run``.

1. Every document is valid against its model: results (``haptify.pipeline.results.ResultsFile``), conformance
   report (``haptify_conform.report.ConformReport``), session manifest (``haptify.formats.session_format.Session``).
2. The documents agree with each other and with ``bundle.json``: spec version, implementation, session
   id, lab, device, rig, and the results' ``manifest_sha256`` is the sha256 of the included manifest.
3. The implementation conforms (:func:`check_conformance`).
4. With raw streams, the session is validated (spec chapter 4) and the reference re-computes every
   submitted metric (:func:`verify`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from haptify.codes import Code
from haptify.errors import Finding, HaptifyError, fail
from haptify.formats.bundle_format import CONFORMANCE_JSON, RESULTS_JSON, SESSION_DIR, Bundle, bundle_digest
from haptify.formats.storage import MANIFEST, open_session, parse_json_file, pydantic_findings, sha256_file
from haptify.metrics.metric_definitions import MetricDefinition, all_families
from haptify.pipeline.results import ResultsFile
from haptify.versions import SPEC_VERSION
from haptify_conform.cases import load_cases, select
from haptify_conform.report import ConformReport
from haptify_tools.registry.bundle import Limits, Unpacked, read_manifest

SUPPORTED_SPEC_VERSIONS = (SPEC_VERSION,)


@dataclass
class MetricCheck:
    """The re-computation of one submitted metric (spec §17.3)."""

    metric: str
    status: str  # agrees | disagrees | unverifiable (one metric's check; the submission's state is disagreeing)
    submitted: Any
    recomputed: Any = None
    tolerance: dict | None = None
    message: str = ""
    code: str | None = None  # W969 when the metric disagrees


@dataclass
class Verification:
    """``verified`` (every metric agrees), ``disagreeing`` (at least one disagrees) or ``unverified`` (no raw
    streams, or only metrics the suite cannot check).
    Spec §17.3.1."""

    status: str
    checks: list[MetricCheck] = field(default_factory=list)
    note: str = ""

    def to_dict(self) -> dict:
        return {"status": self.status, "note": self.note, "checks": [asdict(c) for c in self.checks]}


@dataclass
class Checked:
    """A bundle that passed every content check of :func:`check_bundle` (spec §17.3)."""

    bundle: Bundle
    digest: str
    results: ResultsFile
    conformance: ConformReport | None
    verification: Verification = field(default_factory=lambda: Verification("unverified", note="not re-computed yet"))


_Doc = TypeVar("_Doc", bound=BaseModel)


def _doc(unpacked: Unpacked, path: str, model: type[_Doc], limits: Limits) -> _Doc:
    size = unpacked.members[path][0]
    if size > limits.max_json_bytes:
        raise fail(
            Code.BUNDLE_TOO_LARGE,
            f"{path} is too large",
            file=path,
            expected=f"≤ {limits.max_json_bytes} bytes",
            found=f"{size} bytes",
        )
    data = parse_json_file(unpacked.root / path, Code.BUNDLE_CONTENT_INVALID, path)
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise HaptifyError(*pydantic_findings(exc, Code.BUNDLE_CONTENT_INVALID, path)) from None


def _mismatch(what: str, file: str, pointer: str, expected: Any, found: Any) -> Finding:
    return Finding(
        Code.BUNDLE_CONTENT_INVALID,
        f"{what} differs between bundle.json and {file}",
        file=file,
        pointer=pointer,
        expected=expected,
        found=found,
    )


def check_bundle(unpacked: Unpacked, limits: Limits = Limits()) -> Checked:
    """Run the checks of spec §17.3 steps 2–4 (manifest, documents, an included conformance report); raises
    the findings. The re-computation (step 7) is :func:`verify_bundle`, run after the cheaper checks."""
    bundle = read_manifest(unpacked, limits)
    if bundle.spec_version not in SUPPORTED_SPEC_VERSIONS:
        raise fail(
            Code.BUNDLE_SPEC_VERSION_UNSUPPORTED,
            f"spec version {bundle.spec_version!r} is not accepted",
            file="bundle.json",
            pointer="/spec_version",
            expected=list(SUPPORTED_SPEC_VERSIONS),
            found=bundle.spec_version,
        )
    results = _doc(unpacked, RESULTS_JSON, ResultsFile, limits)
    conformance = _doc(unpacked, CONFORMANCE_JSON, ConformReport, limits) if bundle.file("conformance") else None
    manifest_path = f"{SESSION_DIR}/{MANIFEST}"
    if unpacked.members[manifest_path][0] > limits.max_json_bytes:
        raise fail(
            Code.BUNDLE_TOO_LARGE,
            f"{manifest_path} is too large",
            file=manifest_path,
            expected=f"≤ {limits.max_json_bytes} bytes",
        )
    session = open_session(unpacked.root / SESSION_DIR)
    device = session.device()
    findings: list[Finding] = []
    pairs = [
        ("spec version", RESULTS_JSON, "/spec_version", bundle.spec_version, results.spec_version),
        ("spec version", manifest_path, "/spec_version", bundle.spec_version, session.manifest.spec_version),
        (
            "implementation",
            RESULTS_JSON,
            "/implementation",
            bundle.implementation.model_dump(),
            results.implementation.model_dump(),
        ),
        ("session id", RESULTS_JSON, "/session_id", bundle.session_id, results.session_id),
        ("session id", manifest_path, "/session_id", bundle.session_id, session.session_id),
        ("lab", manifest_path, "/lab/id", bundle.lab.id, session.manifest.lab.id),
        (
            "device",
            manifest_path,
            "/device",
            bundle.device.model_dump(),
            {"manufacturer": device.manufacturer, "model": device.model, "serial": device.serial},
        ),
        ("rig", manifest_path, "/rig", bundle.rig.model_dump(), session.manifest.rig.model_dump()),
    ]
    if results.device is not None:
        pairs.append(("device", RESULTS_JSON, "/device", bundle.device.model_dump(), results.device.model_dump()))
    findings += [_mismatch(w, f, p, e, x) for w, f, p, e, x in pairs if e != x]
    manifest_sha = sha256_file(unpacked.root / manifest_path)
    if results.manifest_sha256 != manifest_sha:
        findings.append(
            Finding(
                Code.BUNDLE_CONTENT_INVALID,
                "the results were not computed from the included session manifest",
                file=RESULTS_JSON,
                pointer="/manifest_sha256",
                expected=manifest_sha,
                found=results.manifest_sha256,
            )
        )
    if not results.metrics:
        findings.append(
            Finding(
                Code.BUNDLE_CONTENT_INVALID,
                "the results contain no metric",
                file=RESULTS_JSON,
                pointer="/metrics",
                expected="at least one metric",
                found=0,
            )
        )
    findings += metric_findings(results)
    if findings:
        raise HaptifyError(*findings)
    if conformance is not None:
        check_conformance(conformance, results, bundle.spec_version)
    return Checked(bundle=bundle, digest=bundle_digest(bundle), results=results, conformance=conformance)


def verify_bundle(checked: Checked, unpacked: Unpacked, enabled: bool = True) -> Verification:
    """Step 7 of spec §17.3: :func:`verify` when the bundle includes raw streams, else ``unverified``."""
    if not checked.bundle.includes_raw:
        return Verification("unverified", note="no raw streams included")
    if not enabled:
        return Verification("unverified", note="re-computation switched off on this registry")
    return verify(unpacked.root / SESSION_DIR, checked.results, checked.bundle.spec_version)


@lru_cache(maxsize=1)
def _definitions() -> dict[str, tuple[MetricDefinition, str]]:
    """Every metric definition of this spec version with its family's definition version."""
    return {m.id: (m, f.version) for f in all_families() for m in f.metrics}


SHAPE_LENGTH = {"vector3": 3, "vector6": 6}


def _e966(i: int, member: str, message: str, expected: Any, found: Any) -> Finding:
    """E966 at ``results.json#/metrics/<i><member>``."""
    return Finding(
        Code.BUNDLE_CONTENT_INVALID, message, file=RESULTS_JSON, pointer=f"/metrics/{i}{member}", expected=expected, found=found
    )


def metric_findings(results: ResultsFile) -> list[Finding]:
    """E966 for each metric record that is not a defined metric in its unit, shape and definition version
    (results computed with other definitions are not comparable; spec §17.3)."""
    out: list[Finding] = []
    defs = _definitions()
    seen: set[str] = set()
    for i, m in enumerate(results.metrics):
        if m.id in seen:
            out.append(_e966(i, "", f"metric {m.id} is reported twice", "each metric once", m.id))
        seen.add(m.id)
        if m.id not in defs:
            out.append(
                _e966(i, "/id", f"{m.id!r} is not a metric of spec {SPEC_VERSION}", "an id from schemas/<v>/metrics", m.id)
            )
            continue
        definition, version = defs[m.id]
        if m.unit != definition.unit:
            out.append(_e966(i, "/unit", f"{m.id} is reported in the wrong unit", definition.unit, m.unit))
        if m.definition_version != version:
            what = f"{m.id} was computed with another definition version"
            out.append(_e966(i, "/definition_version", what, version, m.definition_version))
        length = SHAPE_LENGTH.get(definition.shape)
        found = len(m.value) if isinstance(m.value, list) else None
        if definition.shape == "scalar" and found is not None or length is not None and found != length:
            shape = "scalar" if found is None else f"list of {found}"
            out.append(_e966(i, "/value", f"{m.id} has the wrong shape", definition.shape, shape))
    return out


@lru_cache(maxsize=4)
def _must_cases(spec_version: str) -> dict[str, tuple[str, ...]]:
    """The suite's MUST case ids per metric for ``spec_version``."""
    out: dict[str, list[str]] = {}
    for case in select(load_cases(), level="MUST", spec_version=spec_version):
        out.setdefault(case.metric, []).append(case.id)
    return {k: tuple(v) for k, v in out.items()}


def check_conformance(report: ConformReport, results: ResultsFile, spec_version: str, *, file: str = CONFORMANCE_JSON) -> None:
    """E967 unless ``report`` is a passing run of the results' implementation for ``spec_version`` (spec §17.3).

    Passing means: same spec version; the header's implementation has the results' name and version;
    no case failed or errored (counted from the case records, not taken from the summary); and for every
    submitted metric, every MUST case of the registry's suite for that metric is in the report, passed.
    """
    findings: list[Finding] = []
    if report.header.spec_version != spec_version:
        findings.append(
            Finding(
                Code.CONFORMANCE_NOT_PASSING,
                "the conformance report is for another spec version",
                file=file,
                pointer="/header/spec_version",
                expected=spec_version,
                found=report.header.spec_version,
            )
        )
    impl = {k: report.header.implementation.get(k) for k in ("name", "version")}
    if impl != results.implementation.model_dump():
        findings.append(
            Finding(
                Code.CONFORMANCE_NOT_PASSING,
                "the conformance report is of another implementation",
                file=file,
                pointer="/header/implementation",
                expected=results.implementation.model_dump(),
                found=impl,
            )
        )
    bad = [c.case_id for c in report.cases if c.status in ("failed", "error")]
    if bad or not report.summary.conforms:
        findings.append(
            Finding(
                Code.CONFORMANCE_NOT_PASSING,
                "the implementation does not pass the conformance suite",
                file=file,
                pointer="/summary/conforms",
                expected="no failed or error case",
                found=bad or "conforms: false",
            )
        )
    passed = {c.case_id for c in report.cases if c.status == "passed"}
    must = _must_cases(spec_version)
    for metric in sorted({m.id for m in results.metrics}):
        missing = [cid for cid in must.get(metric, ()) if cid not in passed]
        if missing:
            findings.append(
                Finding(
                    Code.CONFORMANCE_NOT_PASSING,
                    f"the report does not show the MUST cases of {metric} passed",
                    file=file,
                    pointer="/cases",
                    expected=list(must[metric]),
                    found={"not passed": missing},
                )
            )
    if findings:
        raise HaptifyError(*findings)


@lru_cache(maxsize=4)
def tolerances(spec_version: str = SPEC_VERSION) -> dict[str, dict[str, float]]:
    """Per metric, the loosest conformance tolerance: the largest ``abs`` and the largest ``rel`` over
    all its cases for ``spec_version`` (spec §17.3). A metric without cases has no entry."""
    out: dict[str, dict[str, float]] = {}
    for case in select(load_cases(), spec_version=spec_version):
        if case.tolerance is None:
            continue
        tol = out.setdefault(case.metric, {"abs": 0.0, "rel": 0.0})
        tol["abs"] = max(tol["abs"], case.tolerance.abs)
        tol["rel"] = max(tol["rel"], case.tolerance.rel)
    return out


def _flat(value: Any) -> list[float]:
    return [float(v) for v in value] if isinstance(value, list) else [float(value)]


def agrees(submitted: Any, recomputed: Any, tol: dict[str, float]) -> bool:
    """``|s − r| ≤ abs + rel·|r|`` for every component, as the conformance judge (spec §16.3)."""
    s, r = _flat(submitted), _flat(recomputed)
    return len(s) == len(r) and all(math.isfinite(a) and abs(a - b) <= tol["abs"] + tol["rel"] * abs(b) for a, b in zip(s, r))


def verify(session_root: Path, results: ResultsFile, spec_version: str = SPEC_VERSION) -> Verification:
    """Validate the included session and re-compute every submitted metric with the reference (spec §17.3).

    A session with validation errors is refused (E966 with the validator's findings). Each metric is
    compared with the loosest tolerance of its conformance cases; a metric the suite has no case for is
    ``unverifiable`` and keeps the submission from being ``verified``.
    """
    from haptify.formats.validation import validate_session
    from haptify.pipeline.compute import compute_session

    report = validate_session(session_root)
    errors = [f for f in report.findings if f.is_error]
    if errors:
        raise HaptifyError(
            Finding(
                Code.BUNDLE_CONTENT_INVALID,
                f"the included session has {len(errors)} validation error(s)",
                file=f"{SESSION_DIR}/",
                expected="a valid session (spec chapter 4)",
                found=report.codes,
            ),
            *errors,
        )
    ids = sorted({m.id for m in results.metrics})
    recomputed = compute_session(open_session(session_root), metrics=ids)
    unavailable = {u.id: u for u in recomputed.unavailable}
    tols = tolerances(spec_version)
    checks: list[MetricCheck] = []
    for m in sorted(results.metrics, key=lambda m: m.id):
        tol = tols.get(m.id)
        ref = recomputed.get(m.id)
        if tol is None:
            checks.append(
                MetricCheck(
                    m.id,
                    "unverifiable",
                    m.value,
                    ref.value if ref else None,
                    None,
                    "the conformance suite has no tolerance for this metric",
                )
            )
        elif ref is None:
            why = unavailable.get(m.id)
            checks.append(
                MetricCheck(
                    m.id,
                    "disagrees",
                    m.value,
                    None,
                    tol,
                    f"the reference cannot compute it from the included streams: "
                    f"{why.code + ' ' + why.reason if why else 'not computed'}",
                    Code.METRIC_DISAGREES,
                )
            )
        elif agrees(m.value, ref.value, tol):
            checks.append(MetricCheck(m.id, "agrees", m.value, ref.value, tol))
        else:
            checks.append(
                MetricCheck(
                    m.id,
                    "disagrees",
                    m.value,
                    ref.value,
                    tol,
                    f"submitted {m.value!r}, the reference computes {ref.value!r}; "
                    f"allowed |difference| ≤ {tol['abs']:g} + {tol['rel']:g}·|reference|",
                    Code.METRIC_DISAGREES,
                )
            )
    status = "verified" if all(c.status == "agrees" for c in checks) else "disagreeing"
    if status == "disagreeing" and not any(c.status == "disagrees" for c in checks):
        status = "unverified"
    bad = [c.metric for c in checks if c.status != "agrees"]
    return Verification(status, checks, "" if not bad else f"not agreeing: {', '.join(bad)}")
