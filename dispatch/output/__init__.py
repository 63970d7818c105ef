"""What a run writes and prints: the Parquet recorder, the rows its subscribers write, the summary
statistics and the printed tables."""
