"""Files every stage writes or reads the same way: atomic writes and the clash rule, image-file listing,
the sha256 of a file."""
