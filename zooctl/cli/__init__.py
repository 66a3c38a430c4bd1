"""The thin Typer layer. One module per command group; no logic here beyond parsing and printing."""
