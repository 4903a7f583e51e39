"""The session viewer on rerun (issue 7)."""
