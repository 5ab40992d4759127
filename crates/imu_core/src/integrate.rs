//! TODO: filled in by its own change.
