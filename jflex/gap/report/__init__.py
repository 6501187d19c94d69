"""The report: Markdown, HTML and figures written from a diagnosis."""
