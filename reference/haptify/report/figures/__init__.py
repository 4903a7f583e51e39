"""Everything the report draws or plays (spec §15.6): one module per metric family, named as the family
(``haptify.report.figures.<family>``), with ``report_figures(ctx, results)`` and, where the family has sound,
``report_audio(ctx)``. The metric modules compute; these modules only read their results and intermediates.
"""
