"""haptify-conform: the Haptify conformance suite runner (spec chapter 16).

The suite is data (``conformance/cases/*.json`` and ``fixtures/``); this package runs any
implementation against it — through a command per case (``--cmd``), a persistent JSON-lines process
(``--jsonl``) or an in-process Python function (``--python``) — and judges the answers.
"""

PROTOCOL_VERSION = 1
SUITE_VERSION = "1.0.0"
