"""Bridges to other tracking frameworks (each an optional extra, imported only when used)."""
