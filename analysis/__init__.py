"""Analysis of Parquet results (reads Parquet only; no torch or PyBullet needed)."""
