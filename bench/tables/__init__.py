"""Every table of a run, numeric until rendered once (terminal, Markdown, CSV, LaTeX):
:class:`~posbench.tables.table.Table` and the builders that read a run's results."""
