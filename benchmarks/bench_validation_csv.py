"""Cost of validating a 140 s session stored as CSV, and the share of the CSV grammar check (spec §3.2, §4.3.5).

The session is ``bench_io``'s 140 s local-dynamic session with every stream re-written as CSV (the
reference's writer: shortest round-trip decimals). Times ``validate_session`` on it, and
``check_csv_grammar`` alone on every stream file. No target of its own: issue 2's target (< 1 s to
validate and load) concerns the default format, Parquet, and is measured by ``bench_io``.

    python benchmarks/bench_validation_csv.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_io import build  # noqa: E402

from haptify.formats.storage import MANIFEST, check_csv_grammar, read_table, sha256_file, write_table  # noqa: E402
from haptify.formats.validation import validate_session  # noqa: E402


def to_csv(session: Path) -> list[tuple[Path, list[str]]]:
    """Re-write every stream of ``session`` as CSV (manifest updated); the stream files and their columns."""
    manifest = json.loads((session / MANIFEST).read_text(encoding="utf-8"))
    files = []
    for trial in manifest["trials"]:
        for s in trial["streams"]:
            names = [c["name"] for c in s["columns"]]
            old = session / s["file"]
            table = read_table(old, s["format"], names, label=s["file"])
            old.unlink()
            s.update(file=s["file"].removesuffix(".parquet") + ".csv", format="csv")
            write_table(session / s["file"], table, "csv")
            s["sha256"] = sha256_file(session / s["file"])
            files.append((session / s["file"], names))
    (session / MANIFEST).write_text(json.dumps(manifest), encoding="utf-8")
    return files


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        session = build(Path(tmp))
        files = to_csv(session)
        size = sum(p.stat().st_size for p, _ in files)
        validate, grammar = [], []
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            report = validate_session(session)
            t1 = time.perf_counter()
            for path, names in files:
                check_csv_grammar(path, names, path.name)
            t2 = time.perf_counter()
            if not report.valid:
                raise SystemExit("benchmark session is invalid:\n" + "\n".join(str(f) for f in report.errors))
            validate.append(t1 - t0)
            grammar.append(t2 - t1)
    v, g = statistics.median(validate), statistics.median(grammar)
    print(f"session: 140 s as CSV, {len(files)} streams, {size / 2**20:.1f} MiB")
    print(f"validate (CSV): {v:.2f} s median of {args.repeat}; of it the CSV grammar check {g:.2f} s "
          f"({g / v:.0%}), {size / 2**20 / g:.0f} MiB/s (no target)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
