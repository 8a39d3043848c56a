"""The ``bench`` command line: the Typer app (:mod:`posbench.cli.app`), one module per
command, the option types they share (:mod:`posbench.cli.options`), ``--config`` files
(:mod:`posbench.cli.config_file`) and the terminal output (:mod:`posbench.cli.terminal`)."""


def main(argv: list[str] | None = None) -> None:
    """The ``bench`` console script (:func:`posbench.cli.app.main`)."""
    from posbench.cli.app import main as app_main

    app_main(argv)
