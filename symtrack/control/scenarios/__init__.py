"""Built-in MPC path-tracking scenarios (TOML, schema in symtrack.control.scenario)."""
