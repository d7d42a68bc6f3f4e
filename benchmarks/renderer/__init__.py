"""Benchmarks of the renderer alone: they import sim_core and nothing else of the project (an
import-linter contract in pyproject.toml), so they measure the renderer as a user of sim_core
sees it."""
