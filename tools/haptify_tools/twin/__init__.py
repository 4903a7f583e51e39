"""The device twin and virtual rig: simulate every protocol into standard sessions with known truth (design §4; TWIN.md)."""
