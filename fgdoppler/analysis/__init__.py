"""Analysis: observability, bounds, metrics and Monte Carlo studies."""
