"""Everything that draws or plays (spec §15.6): the human report, an HTML page with figures, the results table
and audio (:mod:`.document`), and one figure module per metric family (:mod:`.figures`). Nothing here computes
a metric. The package imports none of its modules.
"""
