"""Session formats (spec chapters 1–5): units, frames and time (:mod:`.conventions`, chapter 1), the session
model (:mod:`.session_format`, chapter 2), storage (:mod:`.storage`, chapter 3), validation split by what it
checks (:mod:`.validation`, chapter 4), the importers, one module per source format (:mod:`.importers`,
:mod:`.c3d_stream`, :mod:`.suggest_map`, chapter 5) and the submission bundle's manifest (:mod:`.bundle_format`,
§17.2). The package imports none of its modules.
"""
