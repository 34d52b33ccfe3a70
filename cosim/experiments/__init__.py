"""The papers' experiments as Monte Carlo campaigns: ``pendulum-cosim experiment NAME``."""
