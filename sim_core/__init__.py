"""sim_core package."""
