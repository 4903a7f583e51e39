"""The session viewer on rerun (design §1)."""
