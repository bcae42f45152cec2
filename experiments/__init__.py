"""Experiments: YAML files, the schema, the runner that launches a run's processes, and the CLI."""
