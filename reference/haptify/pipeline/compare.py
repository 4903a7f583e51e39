"""Comparing devices: the paper's Table III for any number of results files (spec §15.5).

Rows are the Table III metrics in the paper's order (``schemas/<v>/paper-values.json``), shown in the
paper's display units; columns are the devices (one per results file), optionally followed by the
paper's published values. Output as Markdown, CSV or HTML.
"""

from __future__ import annotations

import csv
import html
import io
from dataclasses import dataclass

from haptify import schemas
from haptify.metrics.significance import compared
from haptify.pipeline.results import MetricResult, ResultsFile


@dataclass
class Table:
    """A comparison table: header row and body rows of display strings.
    In the paper's display units; spec §15.5."""

    header: list[str]
    rows: list[list[str]]
    notes: list[str]


def _num(value: float, significant: int) -> str:
    """``significant`` digits, never in exponent form for values of 1000 and more (11799, not 1.2e+04)."""
    return f"{value:.0f}" if abs(value) >= 10**significant else f"{value:.{significant}g}"


def _fmt(value: float | None, sd: float | None = None, expanded: float | None = None) -> str:
    """A table cell: the value to 5 significant digits (the paper's precision), ± U to 2 marked "(U)" when
    it has an uncertainty (spec §19.6), else ± sd to 2."""
    if value is None:
        return "—"
    text = _num(value, 5)
    if expanded is not None:
        text += f" ± {_num(expanded, 2)} (U)"
    elif sd is not None:
        text += f" ± {_num(sd, 2)}"
    return text


def _cell(m: MetricResult | None, factor: float) -> str:
    """A device's cell of a row: "—" for a missing or per-axis metric (spec §15.5, §19.6)."""
    if m is None or isinstance(m.value, list):
        return "—"
    expanded = m.uncertainty.U * factor if m.uncertainty is not None and not isinstance(m.uncertainty.U, list) else None
    return _fmt(m.value * factor, m.sd * factor if isinstance(m.sd, float) else None, expanded)


SIGNIFICANCE = "significant differences"
SIGNIFICANCE_NOTE = (
    "± … (U): expanded uncertainty at 95 % (spec §19.4); ± without (U): the repetitions' sd. "
    "Significant differences: device columns i–j with |x_i − x_j| > k·√(u_i² + u_j²), k Student's t at the "
    "Welch–Satterthwaite degrees of freedom (spec §19.6)."
)


def significance(records: list[MetricResult | None]) -> str:
    """The pairs of device columns (from 1) whose values differ significantly (spec §19.6): "1–2, 2–3",
    "none", or "—" when fewer than two values carry an uncertainty."""
    pairs, tested = [], 0
    for i in range(len(records)):
        for j in range(i + 1, len(records)):
            diff = compared(records[i], records[j])
            if diff is not None:
                tested += 1
                if diff.significant:
                    pairs.append(f"{i + 1}–{j + 1}")
    return ", ".join(pairs) if pairs else ("none" if tested else "—")


def column_label(results: ResultsFile, taken: set[str]) -> str:
    """A device's column heading (spec §15.5): "manufacturer model #serial", plus the session id when already ``taken``."""
    label = results.device.label if results.device else results.session_id
    return label if label not in taken else f"{label} ({results.session_id})"


def build_table(results: list[ResultsFile], with_paper: bool = False) -> Table:
    """The Table III layout for ``results`` (spec §15.5); missing metrics show as '—'."""
    paper = schemas.load("paper-values.json")
    header = ["Metric"]
    taken: set[str] = set()
    for r in results:
        label = column_label(r, taken)
        taken.add(label)
        header.append(label)
    significance_column = sum(any(m.uncertainty is not None for m in r.metrics) for r in results) >= 2
    if significance_column:
        header.append(SIGNIFICANCE)
    if with_paper:
        header += [f"paper: {d}" for d in paper["devices"]]
    rows, notes = [], []
    for row in paper["rows"]:
        factor = row["display_factor"]
        records = [r.get(row["metric"]) for r in results]
        cells = [f"{row['label']} ({row['display_unit']})"] + [_cell(m, factor) for m in records]
        if significance_column:
            cells.append(significance(records))
        if with_paper:
            cells += [_fmt(row["values"][d] * factor) for d in paper["devices"]]
            if "note" in row:
                notes.append(f"{row['label']}: {row['note']}")
        rows.append(cells)
    if any(m.uncertainty is not None for r in results for m in r.metrics):
        notes.append(SIGNIFICANCE_NOTE)
    return Table(header, rows, notes)


def to_markdown(table: Table) -> str:
    """The comparison table as a Markdown table with its notes as a list (``--format md``; spec §15.5)."""
    lines = ["| " + " | ".join(table.header) + " |", "|" + "---|" * len(table.header)]
    lines += ["| " + " | ".join(r) + " |" for r in table.rows]
    lines += [""] + [f"- {n}" for n in table.notes] if table.notes else []
    return "\n".join(lines) + "\n"


def to_csv(table: Table) -> str:
    """The comparison table as CSV, header row first (``--format csv``; spec §15.5)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(table.header)
    writer.writerows(table.rows)
    return buf.getvalue()


def to_html_document(table: Table) -> str:
    """The comparison table as a complete HTML page, UTF-8 (``--format html``; spec §15.5)."""
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        "<title>Haptify comparison</title>\n</head>\n<body>\n" + to_html(table) + "\n</body>\n</html>\n"
    )


def to_html(table: Table) -> str:
    """The comparison table as an HTML fragment, every cell escaped (for pages that embed it; spec §15.5)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in table.header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in table.rows)
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in table.notes)
    return f'<table class="haptify-compare"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>' + (
        f"<ul>{notes}</ul>" if notes else ""
    )
