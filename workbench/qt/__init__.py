"""PySide6 desktop shell (main window, panels, tools)."""
