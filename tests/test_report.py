"""The report (spec §15.6): audio conversion, the Fig. 9 figure, and the whole folder from a fixture."""

from __future__ import annotations

import numpy as np
from conftest import REPO
from scipy.io import wavfile

from haptify.cli.main import main
from haptify.pipeline.results import Implementation, MetricResult, ResultsFile
from haptify.report.document import WAV_RATE_HZ, to_wav_samples
from haptify.report.figures.dynamics import report_figures as dynamics_figures


def test_wav_samples_are_resampled_to_44k1_and_scaled():
    rate = 2000.0
    t = np.arange(4000) / rate  # 2 s of a 100 Hz tone of amplitude 0.5 m/s²
    out = to_wav_samples(0.5 * np.sin(2 * np.pi * 100 * t), rate, scale=0.8443)
    assert out.dtype == np.float32 and len(out) == 2 * WAV_RATE_HZ
    middle = out[WAV_RATE_HZ // 2 : 3 * WAV_RATE_HZ // 2]
    np.testing.assert_allclose(np.max(np.abs(middle)), 0.5 / 0.8443, rtol=2e-3)
    spectrum = np.abs(np.fft.rfft(middle))
    assert np.argmax(spectrum) * WAV_RATE_HZ / len(middle) == 100.0
    assert np.max(np.abs(to_wav_samples(np.array([0.0, 3.0, -3.0, 0.0] * 50), rate, scale=1.0))) <= 1.0


def test_dynamics_figure_plots_every_segment_and_the_line():
    rows = [
        {"trial": "a", "set": "training", "start_s": 0.0, "distance": 0.0, "force_error": 0.1},
        {"trial": "b", "set": "test set 1", "start_s": 0.0, "distance": 1.0, "force_error": 0.3},
        {"trial": "b", "set": "test set 1", "start_s": 5.0, "distance": 2.0, "force_error": 0.5},
    ]
    results = ResultsFile(
        implementation=Implementation(name="t", version="0"),
        session_id="s",
        manifest_sha256="0" * 64,
        metrics=[
            MetricResult(
                id="dynamics.error_vs_distance",
                value=[0.2, 0.1],
                unit="N",
                n=3,
                definition_version="1.0.0",
                diagnostics={"segments": rows},
            )
        ],
    )
    [fig] = dynamics_figures(None, results)
    ax = fig.figure.axes[0]
    assert sum(len(c.get_offsets()) for c in ax.collections) == 3
    line = ax.lines[0]
    np.testing.assert_allclose(line.get_ydata(), [0.1, 0.1 + 0.2 * 2.0])


def test_report_folder_from_a_vibration_fixture(tmp_path, capsys):
    session = REPO / "fixtures" / "conformance" / "vib-tones"
    out = tmp_path / "report"
    assert main(["report", str(session), "-o", str(out)]) == 0
    html = (out / "index.html").read_text()
    assert "vibration.rms" in html and "paper: Touch" in html
    pngs = sorted(p.name for p in out.glob("*.png"))
    wavs = sorted(out.glob("*.wav"))
    assert any(n.startswith("vibration_") for n in pngs) and wavs
    peaks = []
    for wav in wavs:
        rate, data = wavfile.read(wav)
        assert rate == WAV_RATE_HZ
        peaks.append(float(np.max(np.abs(data))))
    assert max(peaks) <= 1.0 and max(peaks) > 0.9  # one common scale: the loudest signal fills the range
    assert main(["report", str(session), "-o", str(out)]) == 2  # exists: refused, kept
    assert (out / "index.html").read_text() == html
    capsys.readouterr()


def test_a_wav_scale_that_is_not_a_positive_amplitude_is_a_usage_error(tmp_path, capsys):
    session = REPO / "fixtures" / "conformance" / "vib-tones"
    for scale in ("0", "-0.8443", "nan", "inf"):
        out = tmp_path / f"report-{scale}"
        assert main(["report", str(session), "-o", str(out), f"--wav-scale={scale}"]) == 2
        assert "E903" in capsys.readouterr().err and not out.exists()
