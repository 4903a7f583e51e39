"""Fill the generated tables of the spec from the normative data (spec §0.3).

A spec chapter marks a generated block with ``<!-- BEGIN GENERATED: <what> [arg] -->`` …
``<!-- END GENERATED -->``. ``<what>`` is ``params <family>`` (a metric family's parameters and
metrics), ``stream-kinds``, ``protocols``, ``codes``, ``import-units``, ``uncertainty`` (the method per metric and the sources of
``uncertainty.json``), ``requirements <chapter>`` (a chapter's
requirement ids) or ``coverage`` (requirement → cases and distinguishing mutants, from the case files and
``conformance/mutants/results.json``). It also writes ``reference/haptify/codes.py``, the :class:`Code` names of
``codes.json`` (:func:`codes_module`). ``--check`` exits 1 when a chapter's tables or the codes module
differ from the data, so neither prose tables nor code names can drift from the definition files.
"""

from __future__ import annotations

import re
import sys
from collections.abc import Sequence
from pathlib import Path

from haptify import schemas
from haptify.metrics.metric_definitions import family
from haptify_conform.coverage import coverage_table, suite_coverage
from haptify_conform.requirements import all_requirements
from haptify_tools.generated_files import generator_main

REPO = Path(__file__).resolve().parents[2]
SPEC_DIR = REPO / "spec"
CODES_MODULE = REPO / "reference" / "haptify" / "codes.py"
BLOCK = re.compile(
    r"(<!-- BEGIN GENERATED: (?P<what>[a-z-]+)(?: (?P<arg>[a-z_0-9]+))? -->\n)(?P<body>.*?)(<!-- END GENERATED -->)", re.S
)


def _cell(value: object) -> str:
    return str(value).replace("|", "\\|").replace("\n", " ")


def _table(header: list[str], rows: Sequence[Sequence[object]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def params_table(name: str) -> str:
    fam = family(name)
    out = f"Definition file `metrics/{name}.json`, version {fam.version}.\n\n"
    if fam.parameters:
        out += _table(
            ["parameter", "value", "unit", "meaning"],
            [[f"`{k}`", f"`{p.value}`", p.unit or "—", p.description] for k, p in fam.parameters.items()],
        )
    if fam.metrics:
        out += "\n" + _table(
            ["metric id", "unit", "shape", "from protocols", "aggregation", "definition"],
            [[f"`{m.id}`", m.unit, m.shape, ", ".join(m.protocols), m.aggregation, m.description] for m in fam.metrics],
        )
    return out


def stream_kinds_table() -> str:
    data = schemas.load("stream-kinds.json")
    rows = []
    for kind, spec in data["kinds"].items():
        if "entity_columns" in spec:
            cols = ", ".join(f"`<entity>_{c['name']}` ({c['unit']})" for c in spec["entity_columns"])
        else:
            cols = ", ".join(f"`{c['name']}` ({c['unit']})" for c in spec["columns"])
            if spec.get("optional_columns"):
                cols += "; optional " + ", ".join(f"`{c['name']}`" for c in spec["optional_columns"])
        rows.append(
            [
                f"`{kind}`",
                cols,
                ", ".join(f"`{f}`" for f in spec["frames"]),
                "yes" if spec["nan_allowed"] else "no",
                spec["recommended_rate_hz"],
                spec["description"],
            ]
        )
    return _table(["kind", "columns after `t` (unit)", "frame", "NaN allowed", "recommended Hz", "content"], rows)


def protocols_table() -> str:
    data = schemas.load("protocols.json")["protocols"]
    rows = [
        [
            f"`{name}`",
            {True: "no (passive)", False: "yes (active)", None: "either"}[p["passive"]],
            ", ".join(f"`{k}`" for k in p["required"]) or "—",
            ", ".join(f"`{k}`" for k in p["recommended"]) or "—",
            p["description"],
        ]
        for name, p in data.items()
    ]
    return _table(["protocol", "powered", "required streams", "recommended streams", "what"], rows)


def codes_table() -> str:
    rows = [
        [f"`{c['code']}`", c["name"], c["severity"], f"§{c['spec_section']}", c["title"], c["hint"]]
        for c in schemas.load("codes.json")["codes"]
    ]
    return _table(["code", "name", "severity", "spec", "meaning", "hint"], rows)


def code_member(name: str) -> str:
    """The :class:`~haptify.codes.Code` member name of a catalogue name: ``session-not-found`` →
    ``SESSION_NOT_FOUND`` (spec §0.4)."""
    return name.upper().replace("-", "_")


def codes_module() -> str:
    """The text of ``reference/haptify/codes.py``: one ``Code`` member per entry of ``codes.json``, in the
    catalogue's order, its value the code and its comment the title and spec section (spec §0.4)."""
    lines = [
        "# Generated from schemas/1.0/codes.json by `python -m haptify_tools.gen_docs`; do not edit by hand.",
        '"""The codes of ``schemas/1.0/codes.json`` as names (spec §0.4): ``Code.SESSION_NOT_FOUND == "E101"``.',
        "",
        "A member is a ``str`` (``StrEnum``), so it formats, compares, hashes and serialises as its code; the",
        "catalogue stays the source of severity, title and hint (:func:`haptify.errors.catalogue`).",
        '"""',
        "",
        "from enum import StrEnum",
        "",
        "",
        "class Code(StrEnum):",
        '    """Every coded finding and error; the member name is the catalogue\'s ``name`` in upper case."""',
        "",
    ]
    for c in schemas.load("codes.json")["codes"]:
        lines += [f"    #: {c['title']} (§{c['spec_section']})", f'    {code_member(c["name"])} = "{c["code"]}"']
    return "\n".join(lines) + "\n"


def import_units_table() -> str:
    rows = [
        [u["dimension"], ", ".join(f"`{s}`" for s in u["spellings"]), u["mul"], u["div"], u.get("note", "")]
        for u in schemas.load("import-units.json")["units"]
    ]
    return _table(["dimension", "spellings", "mul", "div", "note"], rows)


def uncertainty_table() -> str:
    from haptify.metrics.uncertainty import definitions

    d = definitions()
    out = f"Definition file `uncertainty.json`, version {d.version}.\n\n"
    out += _table(
        ["parameter", "value", "unit", "meaning"],
        [[f"`{k}`", f"`{p.value}`", p.unit or "—", p.description] for k, p in d.parameters.items()],
    )
    out += "\n" + _table(
        ["source", "type", "distribution", "figure (component)", "perturbs", "meaning"],
        [
            [
                f"`{k}`",
                s.type,
                s.distribution,
                "—" if s.figure is None else f"`{s.figure}`" + ("" if s.component is None else f" ({s.component})"),
                f"`{s.perturbs}`" if s.perturbs else "—",
                s.description,
            ]
            for k, s in d.sources.items()
        ],
    )
    out += "\n" + _table(
        ["bias", "figure (component)", "unit", "meaning"],
        [
            [
                f"`{k}`",
                ("the trial's own track" if b.figure is None else f"`{b.figure}`")
                + ("" if b.component is None else f" ({b.component})"),
                b.unit,
                b.description,
            ]
            for k, b in d.biases.items()
        ],
    )
    out += "\n" + _table(
        ["metric id", "method", "Type B sources", "bias", "why not (more)"],
        [
            [f"`{k}`", m.method, ", ".join(f"`{s}`" for s in m.sources) or "—", f"`{m.bias}`" if m.bias else "—", m.reason or "—"]
            for k, m in d.metrics.items()
        ],
    )
    return out


def requirements_table(chapter: str) -> str:
    rows = [
        [f"`{r.id}`", r.level, f"§{r.section}", r.statement] for r in all_requirements() if r.section.split(".")[0] == chapter
    ]
    return _table(["id", "level", "spec", "requirement"], rows)


def coverage_appendix() -> str:
    return coverage_table(suite_coverage(REPO / "conformance"))


def render_block(what: str, arg: str | None) -> str:
    if what == "params" and arg:
        return params_table(arg)
    if what == "requirements" and arg:
        return requirements_table(arg)
    return {
        "stream-kinds": stream_kinds_table,
        "protocols": protocols_table,
        "codes": codes_table,
        "import-units": import_units_table,
        "coverage": coverage_appendix,
        "uncertainty": uncertainty_table,
    }[what]()


def regenerate(text: str) -> str:
    return BLOCK.sub(lambda m: m.group(1) + render_block(m.group("what"), m.group("arg")) + m.group(5), text)


def targets() -> dict[Path, str]:
    out = {path: regenerate(path.read_text(encoding="utf-8")) for path in sorted(SPEC_DIR.glob("*.md"))}
    out[CODES_MODULE] = codes_module()
    return out


def main(argv: list[str] | None = None) -> int:
    return generator_main(argv, __doc__.splitlines()[0], "haptify_tools.gen_docs", "spec chapter(s) or codes module", targets)


if __name__ == "__main__":
    sys.exit(main())
