"""The scenario names of the CLI (a contract, DESIGN.md section 5); import-light."""

SCENARIOS = ("goal-change", "env-change", "sample-complexity", "timing")
