"""The Haptify results registry: labs submit verified device results; everyone compares devices (issue 9)."""
