"""Co-simulation master, components, campaigns and command line of pendulum-cosim."""
