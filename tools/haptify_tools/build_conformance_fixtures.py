"""Build the conformance suite's metric fixtures and case files (spec chapter 16) from seeds.

Every session under ``fixtures/conformance/<name>/`` is generated from stated truth — analytic shapes,
analytic signals, springs, damped plate modes, a known Hammerstein–Wiener model — and every expected
value in ``conformance/cases/*.json`` is computed from that truth (closed forms, the spec's own
formulas applied to exactly known inputs, quadratures of analytic integrals), never by running the
reference implementation — by the family modules of :mod:`haptify_tools.conformance_fixtures` (one per
metric family; :mod:`~haptify_tools.conformance_fixtures.suite` gathers them). ``validate.json`` turns
every fixture of ``fixtures/invalid`` and ``fixtures/valid`` into a validate case with the codes of its
sidecar. This module is the command line: build, ``--only`` and ``--check``.

    python -m haptify_tools.build_conformance_fixtures           # (re)build fixtures and case files
    python -m haptify_tools.build_conformance_fixtures --check   # exit 1 when committed files are stale

``--check`` compares logical content (parsed JSON, Parquet column bits, CSV bytes), not timestamps or
the Parquet writer's byte layout.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from haptify_conform.fixture_digest import DIGESTS, snapshot_digest, trees_agree, values_agree
from haptify_tools.conformance_fixtures.records import FIXTURE_DIR
from haptify_tools.conformance_fixtures.suite import all_fixtures, build_fixture, case_documents, write_digests

REPO = Path(__file__).resolve().parents[2]
CASES_DIR = REPO / "conformance" / "cases"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fixtures", type=Path, default=REPO / "fixtures", help="fixtures folder (default: the repository's)")
    parser.add_argument("--cases", type=Path, default=CASES_DIR, help="case folder (default: conformance/cases)")
    parser.add_argument("--check", action="store_true", help="only check that the committed fixtures and cases are current")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="rebuild only these fixtures (case files are always written)")
    args = parser.parse_args(argv)
    fixtures = all_fixtures()
    flat = {fx.name: fx for fxs in fixtures.values() for fx in fxs}
    unknown = sorted(set(args.only or ()) - set(flat))
    if unknown:
        parser.error(f"unknown fixture(s) {unknown}; known: {sorted(flat)}")
    docs = case_documents(fixtures, args.fixtures)
    root = args.fixtures / FIXTURE_DIR
    if args.check:
        stale = []
        with tempfile.TemporaryDirectory(prefix="haptify-conformance-") as tmp:
            for name, fx in flat.items():
                fresh = Path(tmp) / name
                build_fixture(fx, fresh)
                if not (root / name).is_dir() or not trees_agree(fresh, root / name):
                    stale.append(f"fixture {FIXTURE_DIR}/{name}")
        extra = sorted(p.name for p in root.iterdir() if p.is_dir() and p.name not in flat) if root.is_dir() else []
        stale += [f"fixture {FIXTURE_DIR}/{n} is not built by this script" for n in extra]
        recorded = json.loads((root / DIGESTS).read_text(encoding="utf-8"))["digests"] if (root / DIGESTS).is_file() else {}
        if recorded != {n: snapshot_digest(root / n) for n in sorted(flat) if (root / n).is_dir()}:
            stale.append(f"{FIXTURE_DIR}/{DIGESTS}")
        for fname, text in docs.items():
            path = args.cases / fname
            if not path.is_file() or not values_agree(json.loads(path.read_text(encoding="utf-8")), json.loads(text)):
                stale.append(f"case file {fname}")
        for line in stale:
            print(f"stale: {line}")
        print(f"conformance fixtures and cases: {'stale' if stale else 'current'} ({len(flat)} fixtures, {len(docs)} case files)")
        return 1 if stale else 0
    for name in args.only or flat:
        build_fixture(flat[name], root / name)
    write_digests(root, [n for n in flat if (root / n).is_dir()])
    args.cases.mkdir(parents=True, exist_ok=True)
    for fname, text in docs.items():
        (args.cases / fname).write_text(text, encoding="utf-8")
    print(f"built {len(args.only or flat)} fixture(s) under {root} and {len(docs)} case files under {args.cases}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
