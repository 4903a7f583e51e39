"""Build the bad-input fixtures ``fixtures/invalid/`` and the small valid sessions ``fixtures/valid/`` (spec §4.7).

Every invalid fixture is the analytic example session (:mod:`haptify_tools.example_session`, 0.2 s of
data) with ONE deliberate defect (or, for ``several-problems``, a few) applied by a small function of
:mod:`haptify_tools.invalid_fixtures.defects`. Its sidecar ``fixtures/invalid/<name>.expected.json`` states
the codes validation must report — fixed by construction in :mod:`haptify_tools.invalid_fixtures.cases`,
never copied from a validator run — the exit code, and what is broken.

    python -m haptify_tools.build_invalid_fixtures [--out FIXTURES_DIR]
    python -m haptify_tools.build_invalid_fixtures --check   # exit 1 when the committed fixtures are stale

The build is deterministic up to the CPU's rounding; :func:`~haptify_conform.fixture_digest.logical_snapshot` describes a built tree by
content (parsed JSON, table values, symlink targets) and :func:`trees_agree` compares two, so a test can
check that the committed fixtures are current without depending on file timestamps, on the Parquet
writer's version string or on the last bits of numpy's vectorised functions.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

from haptify.formats.storage import atomic_write_json
from haptify_conform.fixture_digest import trees_agree
from haptify_tools.example_session import example_writer
from haptify_tools.invalid_fixtures.cases import CASES, VALID, Case
from haptify_tools.invalid_fixtures.session_edits import DURATION_S

REPO = Path(__file__).resolve().parents[2]


# --- building ---------------------------------------------------------------------------------------


def build_case(case: Case, target: Path) -> None:
    """Write one fixture session to ``target`` (which must not exist)."""
    w = example_writer(session_id=f"fixture-{case.name}", duration_s=DURATION_S, fmt=case.fmt)
    if case.extend is not None:
        case.extend(w)
    w.write(target)
    if case.mutate is not None:
        case.mutate(target)


def sidecar(case: Case) -> dict:
    return {"codes": sorted(set(case.codes)), "exit_code": case.exit_code, "description": case.description}


def build_all(out: Path, only: set[str] | None = None) -> None:
    """(Re)build ``out/valid/<name>`` and ``out/invalid/<name>`` with sidecars, replacing the old ones.

    ``only`` restricts the build to the named fixtures (the others are left as they are).
    """
    out.mkdir(parents=True, exist_ok=True)
    for group, cases in (("valid", VALID), ("invalid", CASES)):
        folder = out / group
        folder.mkdir(exist_ok=True)
        for case in cases:
            if only is not None and case.name not in only:
                continue
            target = folder / case.name
            if target.is_symlink() or target.is_file():
                target.unlink()
            elif target.exists():
                shutil.rmtree(target)
            build_case(case, target)
            atomic_write_json(folder / f"{case.name}.expected.json", sidecar(case))


def stale_fixtures(fixtures: Path, scratch: Path) -> list[str]:
    """The fixtures under ``fixtures/{valid,invalid}`` whose logical content (or sidecar) differs from a fresh
    build into ``scratch``, plus fixture folders this script does not build; empty when all are current."""
    build_all(scratch)
    stale: list[str] = []
    for group, cases in (("valid", VALID), ("invalid", CASES)):
        built, committed = scratch / group, fixtures / group
        names = {c.name for c in cases}
        extra = (
            sorted(p.name for p in committed.iterdir() if p.name.removesuffix(".expected.json") not in names)
            if committed.is_dir()
            else []
        )
        stale += [f"{group}/{n} is not built by this script" for n in extra]
        for case in cases:
            if not (committed / case.name).exists() or not trees_agree(built / case.name, committed / case.name):
                stale.append(f"{group}/{case.name}")
            side = committed / f"{case.name}.expected.json"
            if not side.is_file() or json.loads(side.read_text(encoding="utf-8")) != sidecar(case):
                stale.append(f"{group}/{case.name}.expected.json")
    return stale


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "fixtures", help="fixtures folder (default: the repository's)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="rebuild only these fixtures")
    parser.add_argument("--check", action="store_true", help="only check that the committed fixtures are current")
    args = parser.parse_args(argv)
    known = {c.name for c in VALID + CASES}
    unknown = sorted(set(args.only or ()) - known)
    if unknown:
        parser.error(f"unknown fixture(s) {unknown}; known: {sorted(known)}")
    if args.check:
        with tempfile.TemporaryDirectory(prefix="haptify-fixtures-") as tmp:
            stale = stale_fixtures(args.out, Path(tmp))
        for line in stale:
            print(f"stale: {line}")
        print(f"bad-input and valid fixtures: {'stale' if stale else 'current'} ({len(VALID) + len(CASES)} fixtures)")
        return 1 if stale else 0
    build_all(args.out, set(args.only) if args.only else None)
    built = len(args.only) if args.only else len(VALID) + len(CASES)
    print(f"built {built} fixture(s) under {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
