"""Numbers only: success intervals and verdicts, anytime looks and their correction, sequential comparisons."""
