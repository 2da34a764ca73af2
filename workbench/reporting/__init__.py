"""Measurements and report building (pure)."""
