"""The discrepancy workflow (issue 8, design §5): where twin and measurement disagree, which library
effect explains it, the updated twin, and the gap before and after."""
