"""Performance benchmarks (not tests): `python -m benchmarks` runs them all and writes a Markdown table."""
