"""Readers of a scenario's input files: tables (CSV, Parquet), road networks, trip traces and
start files, the empirical taxi sample and its hourly factors. They import nothing of the engine."""
