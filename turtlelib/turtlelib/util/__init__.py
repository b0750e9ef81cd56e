"""Utilities every module shares: the one way configs are validated, the time base (integer ns)."""
