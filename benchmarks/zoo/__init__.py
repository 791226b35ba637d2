"""The plant zoo of benchmarks/quality.py: plants, their common-random-number truth, tuning methods, statistics."""
