"""The Haptify results registry: labs submit verified device results; everyone compares devices (spec chapter 17)."""
