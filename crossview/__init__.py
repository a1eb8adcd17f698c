"""Glue: the command line, the recording format, scoring, benchmarks and dataset tools."""
