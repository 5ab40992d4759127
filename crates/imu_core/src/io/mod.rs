//! One reader (and writer where users need one) per file format.
