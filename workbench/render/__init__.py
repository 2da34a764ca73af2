"""pyvista visuals and off-screen snapshots; no Qt widgets."""
