"""The scenario names of the CLI (a contract: README, Experiment JSON); import-light."""

SCENARIOS = ("goal-change", "env-change", "sample-complexity", "timing")
