"""Library-level jobs behind the CLI commands (the CLI only parses and prints)."""
