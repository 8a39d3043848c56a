"""One module per `bench` command; `posbench.cli` registers them on the Typer app."""
