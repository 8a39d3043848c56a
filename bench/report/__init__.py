"""report.md and its table files, from a saved run: the Markdown, the notes around its
tables, the data-check section and the glossary. Imports no replay, runner or predictor."""
