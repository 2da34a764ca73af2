"""Scriptable services (one per tool) orchestrating core over model values."""
