"""Small helpers every part may use: exact text (tables, intervals, Markdown) and atomic file writes."""
