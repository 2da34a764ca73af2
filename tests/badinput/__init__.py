"""Bad-input corpus (issue 12): every bad file or value gets a clear message, never a traceback."""
