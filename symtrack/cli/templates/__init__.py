"""The starting files of ``symtrack new KIND`` (one TOML file per kind of run file)."""
