"""Mutants of the reference: realistic wrong implementations the conformance suite must catch (spec §16.8.3).

``haptify_mutants.catalogue`` holds the mutant set — each one mistake a lab engineer could make reading the
spec, patched into the reference for the duration of a run — and ``haptify_mutants.run`` (``make mutants``)
runs the whole suite against every mutant and writes ``conformance/mutants/results.json``.
"""
