"""The validation gate's cost (spec §4.8) and validate against a plain hash-and-decode script.

Builds (or reuses) a simulated 3-repetition Touch dossier — the demo's — and measures, as process CPU
time in fresh subprocesses, each pair run alternately ``REPEATS`` times (the ratio is the median of the
per-pair ratios):

- ``compute`` without the gate (open the session, compute every metric) and with it (validate each stream
  as it is read, then the streams no metric read): target overhead ≤ 10 %;
- ``validate`` against a plain script that only hashes and decodes every stream: target ≤ 1.3×;
- issue 21 item 3: ``compute`` with the gate in place, the whole dossier, ≤ 4 s CPU and ≤ 400 MiB peak
  resident memory (the child's ``ru_maxrss``, imports included).

``python benchmarks/bench_gate.py [DOSSIER]``: DOSSIER is a ``haptify simulate`` output folder (default:
the demo's ``demo-out/touch`` when present, else one simulated into a temporary folder).
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

from figures import report

REPEATS = 5

PLAIN = textwrap.dedent("""
    import hashlib, json, sys, time
    from pathlib import Path
    import pyarrow as pa, pyarrow.parquet as pq
    root = Path(sys.argv[1]); start = time.process_time()
    for trial in json.loads((root / "session.json").read_text())["trials"]:
        for s in trial["streams"]:
            data = (root / s["file"]).read_bytes()
            assert hashlib.sha256(data).hexdigest() == s["sha256"]
            pq.read_table(pa.BufferReader(data)).to_pandas()
    print(time.process_time() - start)
""")
VALIDATE = textwrap.dedent("""
    import sys, time
    from haptify.formats.validation import validate_session
    start = time.process_time(); report = validate_session(sys.argv[1]); assert report.valid
    print(time.process_time() - start)
""")
COMPUTE_UNGATED = textwrap.dedent("""
    import sys, time
    from haptify.pipeline.compute import compute_session
    from haptify.formats.storage import open_session
    start = time.process_time(); compute_session(open_session(sys.argv[1]))
    print(time.process_time() - start)
""")
COMPUTE_GATED = textwrap.dedent("""
    import resource, sys, time
    from haptify.pipeline.compute import compute_session
    from haptify.pipeline.gate import open_checked_session
    start = time.process_time(); session = open_checked_session(sys.argv[1]); compute_session(session); session.finish()
    print(time.process_time() - start, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
""")
COMPUTE_CPU_S, COMPUTE_RSS_MIB = 4.0, 400.0


PEAK_RSS_MIB: list[float] = []    # every gated compute's peak resident memory (MiB)


def cpu_once(script: str, session: Path) -> float:
    """Process CPU time (s) of ``script`` on ``session`` in a fresh interpreter (a second number printed,
    the peak resident memory in MiB, goes to :data:`PEAK_RSS_MIB`)."""
    out = subprocess.run([sys.executable, "-c", script, str(session)], capture_output=True, text=True, check=True)
    values = [float(v) for v in out.stdout.split()]
    PEAK_RSS_MIB.extend(values[1:])
    return values[0]


def paired(base: str, other: str, session: Path) -> tuple[float, float, float]:
    """``base`` and ``other`` run alternately :data:`REPEATS` times: the best CPU time of each and the
    median of the per-pair ratios other/base (pairing cancels the drift of a shared machine)."""
    pairs = [(cpu_once(base, session), cpu_once(other, session)) for _ in range(REPEATS)]
    return min(a for a, _ in pairs), min(b for _, b in pairs), statistics.median(b / a for a, b in pairs)


DEMO = Path(__file__).resolve().parents[1] / "demo-out" / "touch"


def dossier(arg: str | None, tmp: Path) -> Path:
    """The session of dossier ``arg``; by default the demo's (``make demo``) when present, else one simulated
    into ``tmp`` exactly as the demo does."""
    if arg or (DEMO / "session").is_dir():
        return Path(arg or DEMO) / "session"
    out = tmp / "touch"
    subprocess.run([sys.executable, "-m", "haptify.cli.main", "simulate", "--preset", "touch", "--protocol", "all", "--reps", "3",
                    "--seed", "1", "-o", str(out)], check=True, capture_output=True)
    return out / "session"


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        session = dossier(sys.argv[1] if len(sys.argv) > 1 else None, Path(tmp))
        plain, validate, v_ratio = paired(PLAIN, VALIDATE, session)
        ungated, gated, g_ratio = paired(COMPUTE_UNGATED, COMPUTE_GATED, session)
    print(f"validate: {validate:.2f} s CPU; plain hash-and-decode: {plain:.2f} s; ratio {v_ratio:.2f} (target ≤ 1.3)")
    print(f"compute without the gate: {ungated:.2f} s CPU; with it: {gated:.2f} s; "
          f"overhead {100 * (g_ratio - 1):+.1f} % (target ≤ 10 %)")
    rss = max(PEAK_RSS_MIB)
    print(f"compute with the gate: {gated:.2f} s CPU (target ≤ {COMPUTE_CPU_S:g} s), peak RSS {rss:.0f} MiB "
          f"(target ≤ {COMPUTE_RSS_MIB:g} MiB)")
    report("validate, demo dossier", "≤ 1.3× the plain script", f"{validate:.2f} s CPU",
           f"hash-and-decode script {plain:.2f} s CPU", v_ratio, holds=v_ratio <= 1.3)
    report("compute: the gate's overhead", "≤ +10 %", f"{gated:.2f} s CPU", f"compute without the gate {ungated:.2f} s CPU",
           g_ratio, holds=g_ratio <= 1.10)
    report("compute with the gate, demo dossier (every family, dynamics fit included)",
           f"≤ {COMPUTE_CPU_S:g} s CPU, ≤ {COMPUTE_RSS_MIB:g} MiB", f"{gated:.2f} s CPU, {rss:.0f} MiB peak RSS",
           holds=gated <= COMPUTE_CPU_S and rss <= COMPUTE_RSS_MIB)
    return 0


if __name__ == "__main__":
    sys.exit(main())
