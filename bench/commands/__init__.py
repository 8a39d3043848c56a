"""One module per `bench` command; `bench.cli` registers them on the Typer app."""
