"""Small helpers every part may use: exact text (numbers, tables, intervals, Markdown), node paths, option text read
by the argument rules, atomic file writes and a user's module imported."""
