"""The bad-input and small valid fixture sessions built by :mod:`haptify_tools.build_invalid_fixtures` (spec §4.7):
session-folder edits, the deliberate defects and the fixture cases."""
