"""Small helpers every stage shares: atomic writes, file digests, the machine's name, the optional
extras and their one-line error."""
