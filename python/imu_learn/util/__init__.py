"""Small helpers every stage shares: atomic writes, output folders written whole (staging.py), Ctrl-C
held out of C++ callbacks (interrupts.py), file digests, the machine's name, the optional extras and
their one-line error."""
