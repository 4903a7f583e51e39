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
from haptify.results import ResultsFile


@dataclass
class Table:
    """A comparison table: header row and body rows of display strings.
    In the paper's display units; spec §15.5."""

    header: list[str]
    rows: list[list[str]]
    notes: list[str]


def _num(value: float, significant: int) -> str:
    """``significant`` digits, never in exponent form for values of 1000 and more (11799, not 1.2e+04)."""
    return f"{value:.0f}" if abs(value) >= 10 ** significant else f"{value:.{significant}g}"


def _fmt(value: float | None, sd: float | None = None) -> str:
    """A table cell: the value to 5 significant digits (the paper's precision), ± sd to 2."""
    if value is None:
        return "—"
    text = _num(value, 5)
    if sd is not None:
        text += f" ± {_num(sd, 2)}"
    return text


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
    if with_paper:
        header += [f"paper: {d}" for d in paper["devices"]]
    rows, notes = [], []
    for row in paper["rows"]:
        factor = row["display_factor"]
        cells = [f"{row['label']} ({row['display_unit']})"]
        for r in results:
            m = r.get(row["metric"])
            if m is None or isinstance(m.value, list):
                cells.append("—")
            else:
                sd = m.sd * factor if isinstance(m.sd, float) else None
                cells.append(_fmt(m.value * factor, sd))
        if with_paper:
            cells += [_fmt(row["values"][d] * factor) for d in paper["devices"]]
            if "note" in row:
                notes.append(f"{row['label']}: {row['note']}")
        rows.append(cells)
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
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<title>Haptify comparison</title>\n</head>\n<body>\n" + to_html(table) + "\n</body>\n</html>\n")


def to_html(table: Table) -> str:
    """The comparison table as an HTML fragment, every cell escaped (for pages that embed it; spec §15.5)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in table.header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in table.rows)
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in table.notes)
    return (f"<table class=\"haptify-compare\"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
            + (f"<ul>{notes}</ul>" if notes else ""))
