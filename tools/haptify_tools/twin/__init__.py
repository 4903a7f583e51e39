"""The device twin and virtual rig: simulate every protocol into standard sessions with known truth (issue 3)."""
