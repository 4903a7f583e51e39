"""The discrepancy workflow (design §5; discrepancy README): where twin and measurement disagree, which library
effect explains it, the updated twin, and the gap before and after."""
