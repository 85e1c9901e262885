"""One run: its options and their one check, the pipeline that composes its source, the
attributes of each chunk, the output frame and precision, and the columns writers take."""
