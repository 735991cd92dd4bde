"""The scenario names of the CLI (a contract: docs/experiments.md); import-light."""

SCENARIOS = ("goal-change", "env-change", "sample-complexity", "timing")
