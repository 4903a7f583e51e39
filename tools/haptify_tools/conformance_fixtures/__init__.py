"""The conformance suite's metric fixtures and cases (spec chapter 16), built by
:mod:`haptify_tools.build_conformance_fixtures`: the case records and shared truth, one module per metric
family (workspace, free space and its processing chain, vibration, uncertainty, surface, stiffness, rig, local
dynamics) and the suite that turns them into fixture folders, case files and digests."""
