"""The Case document and its parts: plain data, no Qt, no VTK."""
