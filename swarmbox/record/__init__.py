"""Per-node logs: one declared, versioned schema; buffered, atomic Parquet writers."""
