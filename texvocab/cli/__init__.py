"""Command-line front end: one module per command group (the last layer)."""
