"""The human report: an HTML page with figures, the results table and audio (spec §15.6).

Figures live apart from the metrics, in :mod:`haptify.report.figures` (one module per family; a plugin family
may draw in its own module): ``report_figures(ctx, results) -> list[ReportFigure]`` (matplotlib figures in
the spirit of the paper's Figs. 5–11) and ``report_audio(ctx) -> list[ReportAudio]`` (signals to render as
WAV). This module gathers them, writes PNGs, WAVs and ``index.html`` into a temporary folder and renames it into
place, so an interrupted report never leaves half a folder.
"""

from __future__ import annotations

import html
import importlib
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from haptify.formats.storage import atomic_write_text, replace_folder_atomically
from haptify.pipeline.compare import build_table, to_html
from haptify.pipeline.compute import ComputeContext
from haptify.pipeline.families import family_modules
from haptify.pipeline.results import ResultsFile

WAV_RATE_HZ = 44_100  # the paper's audio rate (§VI-C)


@dataclass
class ReportFigure:
    """One figure of the report: a file stem, a caption and the matplotlib figure (spec §15.6)."""

    name: str
    caption: str
    figure: Any


@dataclass
class ReportAudio:
    """A signal to render as a WAV file: ``samples`` (SI units) at ``rate_hz`` (spec §15.6)."""

    name: str
    caption: str
    samples: np.ndarray
    rate_hz: float


def to_wav_samples(signal: np.ndarray, rate_hz: float, scale: float) -> np.ndarray:
    """Resample to 44.1 kHz (polyphase, scipy.signal.resample_poly) and divide by ``scale`` (spec §15.6).

    The paper divided every device's signal by the largest absolute value of the Touch's signal
    (0.8443 m/s²) so that the files are comparable; ``scale`` plays that role. Values are clipped to ±1.
    """
    from fractions import Fraction

    from scipy.signal import resample_poly

    ratio = Fraction(WAV_RATE_HZ / rate_hz).limit_denominator(10_000)
    resampled = resample_poly(np.asarray(signal, dtype=float), ratio.numerator, ratio.denominator)
    return np.clip(resampled / scale, -1.0, 1.0).astype(np.float32)


def _html_page(session_id: str, results: ResultsFile, figures: list[ReportFigure], audio: list[tuple[str, str]]) -> str:
    rows = "".join(
        f"<tr><td><code>{html.escape(m.id)}</code></td><td>{html.escape(_value(m.value))}</td>"
        f"<td>{html.escape(m.unit)}</td><td>{m.n}</td><td>{html.escape(_value(m.sd) if m.sd is not None else '—')}</td>"
        f"<td>{html.escape(_value(m.uncertainty.U) if m.uncertainty else '—')}</td>"
        f"<td>{html.escape(f'{m.uncertainty.k:.3g}' if m.uncertainty else '—')}</td></tr>"
        for m in results.metrics
    )
    missing = "".join(
        f"<li><code>{html.escape(u.id)}</code>: {html.escape(u.code)} {html.escape(u.reason)}</li>" for u in results.unavailable
    )
    warnings = "".join(f"<li>{html.escape(w.code)}: {html.escape(w.message)}</li>" for w in results.warnings)
    figs = "".join(
        f'<figure><img src="{html.escape(f.name)}.png" alt="{html.escape(f.caption)}">'
        f"<figcaption>{html.escape(f.caption)}</figcaption></figure>"
        for f in figures
    )
    sounds = "".join(f'<p>{html.escape(c)}<br><audio controls src="{html.escape(n)}.wav"></audio></p>' for n, c in audio)
    device = results.device.label if results.device else ""
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>Haptify report — {html.escape(session_id)}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px}}figure{{margin:1.5em 0}}img{{max-width:100%}}</style></head>
<body><h1>Haptify report</h1><p>Session <code>{html.escape(session_id)}</code> · {html.escape(device)} ·
{html.escape(results.implementation.name)} {html.escape(results.implementation.version)} · spec {html.escape(results.spec_version)}</p>
<h2>Benchmarks (the paper's Table III)</h2>{to_html(build_table([results], with_paper=True))}
<h2>Every metric</h2><table><thead><tr><th>metric</th><th>value</th><th>unit</th><th>n</th><th>sd</th><th>U (95 %, spec §19.4)</th><th>k</th></tr></thead>
<tbody>{rows}</tbody></table>
{f"<h2>Not computed</h2><ul>{missing}</ul>" if missing else ""}
{f"<h2>Warnings</h2><ul>{warnings}</ul>" if warnings else ""}
<h2>Figures</h2>{figs}
{f"<h2>Vibrations as sound</h2>{sounds}" if sounds else ""}
</body></html>
"""


def _value(v: Any) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
    return f"{v:.6g}"


def figure_modules() -> list[Any]:
    """Per family, in the families' order, the module that draws its report: ``haptify.report.figures.<family>`` for the
    reference's families; a family without one there (a plugin's) draws in its own module."""
    out = []
    for family, module_name in family_modules():
        try:
            out.append(importlib.import_module(f"haptify.report.figures.{family}"))
        except ModuleNotFoundError as exc:
            if exc.name != f"haptify.report.figures.{family}":
                raise
            out.append(importlib.import_module(module_name))
    return out


def write_report(
    ctx: ComputeContext, results: ResultsFile, out_dir: Path, *, wav_scale: float | None = None, overwrite: bool = False
) -> Path:
    """Write ``out_dir`` with index.html, one PNG per figure and one WAV per audio signal (spec §15.6)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.io import wavfile

    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    build = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.tmp-", dir=out_dir.parent))
    try:
        figures: list[ReportFigure] = []
        audio: list[ReportAudio] = []
        for module in figure_modules():
            if hasattr(module, "report_figures"):
                figures += module.report_figures(ctx, results)
            if hasattr(module, "report_audio"):
                audio += module.report_audio(ctx)
        for fig in figures:
            fig.figure.savefig(build / f"{fig.name}.png", dpi=110, bbox_inches="tight")
            plt.close(fig.figure)
        scale = wav_scale or max((float(np.max(np.abs(a.samples))) for a in audio), default=1.0) or 1.0
        for a in audio:
            wavfile.write(build / f"{a.name}.wav", WAV_RATE_HZ, to_wav_samples(a.samples, a.rate_hz, scale))
        atomic_write_text(build / "results.json", results.model_dump_json(indent=2) + "\n")
        atomic_write_text(
            build / "index.html", _html_page(results.session_id, results, figures, [(a.name, a.caption) for a in audio])
        )
        replace_folder_atomically(build, out_dir, overwrite)
    except BaseException:
        shutil.rmtree(build, ignore_errors=True)
        raise
    return out_dir
