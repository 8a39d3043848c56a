"""A run as a rerun recording (``bench run --rerun``): the writer, its default layout and
the web viewer (``bench view --web``). Needs the ``viz`` extra, imported only when used."""
