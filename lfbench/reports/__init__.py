"""Tables (markdown, LaTeX, CSV) and figures (PNG) from Results."""
