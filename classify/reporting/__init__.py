"""What an experiment measured: intervals and paired comparisons (``stats``), rate cells and
results (``results``), and their Markdown tables, CSV/JSON files and pictures (``report``)."""
