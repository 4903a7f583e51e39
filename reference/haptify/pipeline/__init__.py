"""Running the metric families over a session and its results document (spec chapter 15, §4.8): the validation
gate (:mod:`.gate`, §4.8), which module computes each family (:mod:`.families`), the context a family
receives (:mod:`.context`), computing every metric a session allows (:mod:`.compute`, §15.4), per-repetition
values into one record (:mod:`.repetitions`, §15.2–15.3), the results file (:mod:`.results`, chapter 15) and
the comparison of devices (:mod:`.compare`, §15.5). The package imports none of its modules.
"""
