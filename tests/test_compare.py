"""Comparison tables (spec §15.5) from results with known values."""

from __future__ import annotations

import json

from haptify.cli.main import main
from haptify.pipeline.compare import build_table, to_csv, to_html, to_markdown
from haptify.pipeline.results import DeviceSummary, Implementation, MetricResult, ResultsFile


def _results(model: str, force: float, volume: float) -> ResultsFile:
    return ResultsFile(
        implementation=Implementation(name="test", version="0"),
        session_id=f"s-{model}",
        device=DeviceSummary(manufacturer="Acme", model=model),
        manifest_sha256="0" * 64,
        metrics=[
            MetricResult(
                id="free_space.force_mean",
                value=force,
                unit="N",
                per_repetition=[force - 0.1, force + 0.1],
                n=2,
                sd=0.1414,
                definition_version="1.0.0",
            ),
            MetricResult(id="workspace.measured_volume", value=volume, unit="m^3", n=1, definition_version="1.0.0"),
        ],
    )


def test_table_has_paper_rows_devices_and_display_units():
    table = build_table([_results("A", 0.5, 0.0125), _results("B", 1.25, 0.0100)], with_paper=True)
    assert table.header == ["Metric", "Acme A", "Acme B", "paper: Touch", "paper: Touch X"]
    volume = next(r for r in table.rows if r[0].startswith("Workspace volume"))
    assert volume[1:3] == ["12500", "10000"]  # m³ shown in cm³
    assert volume[3:] == ["11799", "10418"]
    force = next(r for r in table.rows if r[0].startswith("Mean free-space force"))
    assert force[1] == "0.5 ± 0.14" and force[2] == "1.25 ± 0.14"
    vib = next(r for r in table.rows if r[0].startswith("Free-space vibration RMS"))
    assert vib[1:3] == ["—", "—"]  # not computed is shown, never invented
    assert any("2.7 N" in n for n in table.notes)


def test_renderers_carry_every_cell():
    table = build_table([_results("A", 0.5, 0.0125)])
    md, csv_text, html_text = to_markdown(table), to_csv(table), to_html(table)
    for cell in ("Acme A", "12500", "0.5 ± 0.14"):
        assert cell in md and cell in csv_text and cell in html_text
    assert len(csv_text.strip().splitlines()) == 1 + len(table.rows)


def test_compare_command_writes_file_and_rejects_bad_json(tmp_path, capsys):
    a = tmp_path / "a.json"
    a.write_text(_results("A", 0.5, 0.0125).model_dump_json())
    out = tmp_path / "table.csv"
    assert main(["compare", str(a), "--format", "csv", "-o", str(out)]) == 0
    assert "Acme A" in out.read_text()
    assert f"wrote {out}" in capsys.readouterr().out
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"spec_version": "1.0"}))
    assert main(["--json", "compare", str(bad)]) == 2
    report = json.loads(capsys.readouterr().out)
    assert report["findings"][0]["code"] == "E104" and report["findings"][0]["file"] == str(bad)


def test_the_html_table_is_a_complete_utf8_page(tmp_path):
    from html.parser import HTMLParser

    a = tmp_path / "a.json"
    a.write_text(_results("Ä", 0.5, 0.0125).model_dump_json())
    out = tmp_path / "table.html"
    assert main(["compare", str(a), "--format", "html", "-o", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    tags: list[tuple[str, dict]] = []

    class Tags(HTMLParser):
        def handle_starttag(self, tag, attrs):
            tags.append((tag, dict(attrs)))

    Tags().feed(text)
    names = [t for t, _ in tags]
    assert text.startswith("<!DOCTYPE html>") and names[:3] == ["html", "head", "meta"]
    assert tags[2][1] == {"charset": "utf-8"} and "title" in names and names.index("table") > names.index("body")
    assert "Acme Ä" in text
