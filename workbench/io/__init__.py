"""File formats: meshes, volumes, landmarks, tables, case files."""
