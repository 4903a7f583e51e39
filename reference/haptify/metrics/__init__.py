"""The metric chapters, one module per chapter, pure computation (spec chapters 8–10, 12–14 and 19): workspace
(:mod:`.workspace`, chapter 8, with :mod:`.volume_operator`, §8.4–8.5), free-space forces (:mod:`.free_space`,
chapter 9), vibrations (:mod:`.vibration`, chapter 10), surface (:mod:`.surface`, chapter 12), stiffness
(:mod:`.stiffness`, chapter 13), the rig (:mod:`.rig_checks`, chapter 14), uncertainty and significance
(:mod:`.uncertainty`, :mod:`.significance`, chapter 19) and the definitions' parameters
(:mod:`.metric_definitions`, §0.3). Figures are drawn in :mod:`haptify.report.figures`; the local dynamic
model (chapter 11) is :mod:`haptify.dynamics`. The package imports none of its modules.
"""
